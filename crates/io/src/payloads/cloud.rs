//! `sensor_msgs/PointCloud2` payloads into flat point arrays: any field layout,
//! either byte order, every length checked against the data before anything is
//! reserved.

use travmap_core::frame::RemissionScale;
use travmap_formats::ros::{PointCloud2, PointField, datatype};

/// Reads one numeric value of a field as f64.
fn read_value(bytes: &[u8], datatype_id: u8, big_endian: bool) -> f64 {
    macro_rules! get {
        ($t:ty, $n:literal) => {{
            let mut raw = [0u8; $n];
            raw.copy_from_slice(&bytes[..$n]);
            if big_endian {
                <$t>::from_be_bytes(raw) as f64
            } else {
                <$t>::from_le_bytes(raw) as f64
            }
        }};
    }
    match datatype_id {
        datatype::INT8 => bytes[0] as i8 as f64,
        datatype::UINT8 => bytes[0] as f64,
        datatype::INT16 => get!(i16, 2),
        datatype::UINT16 => get!(u16, 2),
        datatype::INT32 => get!(i32, 4),
        datatype::UINT32 => get!(u32, 4),
        datatype::FLOAT32 => get!(f32, 4),
        _ => get!(f64, 8),
    }
}

/// The points of a cloud as the method reads them.
pub struct CloudPoints {
    /// x, y, z, intensity on a 0..1 scale (0 when `remission` is not usable).
    pub points: Vec<[f32; 4]>,
    /// The scale the intensity field came on.
    pub remission: RemissionScale,
    /// The `label` field, when present.
    pub labels: Option<Vec<u32>>,
    /// Points dropped as no return ([`is_return`]).
    pub dropped: usize,
}

/// Whether a point of a scan (in its sensor's frame) is a return: every coordinate
/// finite, and not exactly the sensor's origin, where Ouster scans and organised
/// clouds put a beam that came back with nothing (41 % of the shipped RELLIS-3D
/// scan), which would otherwise pile up as an obstacle under the sensor.
pub fn is_return(x: f32, y: f32, z: f32) -> bool {
    x.is_finite() && y.is_finite() && z.is_finite() && !(x == 0.0 && y == 0.0 && z == 0.0)
}

/// The problem of a scan none of whose points is a return: mapping it would score
/// an empty grid as if the scene were empty.
pub fn check_some_finite(kept: usize, dropped: usize) -> Result<(), String> {
    if kept == 0 && dropped > 0 {
        return Err(format!(
            "every one of its {dropped} points has a NaN or infinite coordinate or lies at the sensor's origin (no return): nothing to map (a covered or failed sensor?); --keep-going skips the frame"
        ));
    }
    Ok(())
}

/// Reads x, y, z, intensity and label; points that are no return ([`is_return`])
/// are dropped.
pub fn cloud_points(cloud: &PointCloud2) -> Result<CloudPoints, String> {
    let (mut points, intensity_datatype) = raw_cloud_points(cloud)?;
    points.remission = normalise_remission(&mut points.points, intensity_datatype);
    Ok(points)
}

/// [`cloud_points`] with the intensity as the cloud holds it (`remission` is
/// `Missing`), and the intensity field's datatype: for a cloud read in pieces, whose
/// scale is decided over all of them ([`remission_scale`]).
pub fn raw_cloud_points(cloud: &PointCloud2) -> Result<(CloudPoints, Option<u8>), String> {
    let field = |names: &[&str]| {
        cloud
            .fields
            .iter()
            .find(|f| names.contains(&f.name.as_str()))
    };
    let checked = |name: &str, f: &PointField| -> Result<(usize, u8), String> {
        let size = datatype::size(f.datatype)
            .ok_or_else(|| format!("field `{name}` has unknown datatype {}", f.datatype))?;
        if f.offset as usize + size > cloud.point_step as usize {
            return Err(format!(
                "field `{name}` (offset {}, {size} bytes) lies outside point_step {}",
                f.offset, cloud.point_step
            ));
        }
        Ok((f.offset as usize, f.datatype))
    };
    let mut xyz = Vec::new();
    for name in ["x", "y", "z"] {
        let f = field(&[name]).ok_or_else(|| {
            format!(
                "no `{name}` field (fields: {:?})",
                cloud.fields.iter().map(|f| &f.name).collect::<Vec<_>>()
            )
        })?;
        xyz.push(checked(name, f)?);
    }
    // Ouster's driver writes the calibrated 8-bit reflectivity (the packets' own, in
    // a uint16) beside an `intensity` that is the return's photon count.
    let intensity = field(&["reflectivity"])
        .or_else(|| field(&["intensity", "remission", "i"]))
        .map(|f| checked(&f.name, f))
        .transpose()?;
    let label = field(&["label"]).map(|f| checked("label", f)).transpose()?;
    let (width, height) = (cloud.width as usize, cloud.height as usize);
    let (step, row_step) = (cloud.point_step as usize, cloud.row_step as usize);
    // In u128: four u32 header fields multiplied and added can pass 2^64.
    let row_bytes = width as u128 * step as u128;
    let needed = if height == 0 || width == 0 {
        0
    } else {
        (height as u128 - 1) * row_step as u128 + row_bytes
    };
    if needed == 0 && !cloud.data.is_empty() {
        return Err(format!(
            "width {width} x height {height} describes no points, yet data holds {} bytes ({} points of point_step {step}): the driver left the header unfilled",
            cloud.data.len(),
            cloud.data.len().checked_div(step).unwrap_or(0)
        ));
    }
    if (row_step as u128) < row_bytes || (cloud.data.len() as u128) < needed {
        return Err(format!(
            "data holds {} bytes; width {width} x height {height} with point_step {step} and row_step {row_step} need {needed}",
            cloud.data.len()
        ));
    }
    let mut points = Vec::with_capacity(width * height);
    let mut labels = label.map(|_| Vec::with_capacity(width * height));
    let mut dropped = 0;
    let big = cloud.is_bigendian;
    // Little-endian float32 coordinates and intensity, as nearly every driver
    // writes them, are read without the per-value type dispatch: the same values,
    // at a fraction of the cost.
    let float32 = |field: &(usize, u8)| field.1 == datatype::FLOAT32;
    let plain = !big && xyz.iter().chain(&intensity).all(float32);
    // Every row lies inside `data` (checked above) once there are points, and
    // `checked` keeps every field inside a point, so `step` is at least 1.
    let rows = if width == 0 { 0 } else { height };
    let row_bytes = row_bytes as usize;
    // The common layout (x, y, z one after another, intensity anywhere, no label):
    // each point's coordinates are read as one 12-byte array.
    let contiguous = xyz[1].0 == xyz[0].0 + 4 && xyz[2].0 == xyz[0].0 + 8;
    if plain && contiguous && label.is_none() {
        let (at, intensity_at) = (xyz[0].0, intensity.map(|(offset, _)| offset));
        let le = |bytes: &[u8]| f32::from_le_bytes([bytes[0], bytes[1], bytes[2], bytes[3]]);
        for row in 0..rows {
            let row_data = &cloud.data[row * row_step..row * row_step + row_bytes];
            for point in row_data.chunks_exact(step) {
                let coordinates: &[u8; 12] = point[at..at + 12].try_into().expect("12 bytes");
                let (x, y, z) = (
                    le(&coordinates[0..4]),
                    le(&coordinates[4..8]),
                    le(&coordinates[8..12]),
                );
                if !is_return(x, y, z) {
                    dropped += 1;
                    continue;
                }
                points.push([x, y, z, intensity_at.map_or(0.0, |i| le(&point[i..i + 4]))]);
            }
        }
    } else {
        for row in 0..rows {
            let row_data = &cloud.data[row * row_step..row * row_step + row_bytes];
            for point in row_data.chunks_exact(step) {
                let value = |(offset, datatype_id): (usize, u8)| {
                    read_value(&point[offset..], datatype_id, big)
                };
                let read = |field: (usize, u8)| {
                    if plain {
                        let bytes = &point[field.0..field.0 + 4];
                        f32::from_le_bytes([bytes[0], bytes[1], bytes[2], bytes[3]])
                    } else {
                        value(field) as f32
                    }
                };
                let (x, y, z) = (read(xyz[0]), read(xyz[1]), read(xyz[2]));
                if !is_return(x, y, z) {
                    dropped += 1;
                    continue;
                }
                points.push([x, y, z, intensity.map_or(0.0, read)]);
                if let (Some(labels), Some(field)) = (labels.as_mut(), label) {
                    labels.push(value(field) as u32);
                }
            }
        }
    }
    Ok((
        CloudPoints {
            points,
            labels,
            remission: RemissionScale::Missing,
            dropped,
        },
        intensity.map(|(_, datatype)| datatype),
    ))
}

/// Brings the intensity of `points` to 0..1 by its field's type and range: uint8,
/// uint16 and floats up to 255 are Velodyne's (and Ouster's reflectivity's) 0..255;
/// floats up to 1 are KITTI's own; any other scale is not guessed at (divided by
/// its largest value, and said so by the returned scale: only its order is used).
fn normalise_remission(points: &mut [[f32; 4]], datatype_id: Option<u8>) -> RemissionScale {
    let largest = points.iter().map(|p| p[3]).fold(0.0f32, f32::max);
    let (scale, factor) = remission_scale(datatype_id, largest);
    if scale != RemissionScale::Unit {
        for p in points.iter_mut() {
            p[3] *= factor;
        }
    }
    scale
}

/// The scale of an intensity field of type `datatype_id` whose largest value is
/// `largest`, and the factor that brings it to 0..1 (by its largest value for a
/// scale not guessed at).
pub fn remission_scale(datatype_id: Option<u8>, largest: f32) -> (RemissionScale, f32) {
    let Some(datatype_id) = datatype_id else {
        return (RemissionScale::Missing, 0.0);
    };
    let scale = match datatype_id {
        datatype::UINT8 => RemissionScale::Byte,
        datatype::UINT16 if largest <= 255.0 => RemissionScale::Byte,
        datatype::FLOAT32 | datatype::FLOAT64 if largest <= 1.0 => RemissionScale::Unit,
        datatype::FLOAT32 | datatype::FLOAT64 if largest <= 255.0 => RemissionScale::Byte,
        _ => RemissionScale::Unknown,
    };
    let factor = match scale {
        RemissionScale::Unit => 1.0,
        RemissionScale::Byte => 1.0 / 255.0,
        RemissionScale::Unknown if largest > 0.0 => 1.0 / largest,
        _ => 0.0,
    };
    (scale, factor)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// x, y, z, intensity float32 in a 20-byte point, rows padded to 48 bytes.
    fn cloud(width: u32, height: u32, rows: &[&[[f32; 4]]]) -> PointCloud2 {
        let mut fields = PointField::xyz_float32();
        fields.push(PointField::scalar("intensity", 12, datatype::FLOAT32));
        let mut data = Vec::new();
        for row in rows {
            for p in *row {
                p.iter()
                    .for_each(|v| data.extend_from_slice(&v.to_le_bytes()));
                data.extend_from_slice(&[0xAB; 4]);
            }
            data.resize(data.len() + 48 - 20 * row.len(), 0xCD);
        }
        PointCloud2 {
            height,
            width,
            fields,
            point_step: 20,
            row_step: 48,
            data,
            ..Default::default()
        }
    }

    #[test]
    fn points_are_read_row_by_row_past_the_padding_and_non_finite_ones_dropped() {
        let rows: [&[[f32; 4]]; 2] = [
            &[[1.0, 2.0, 3.0, 0.5], [f32::NAN, 0.0, 0.0, 0.1]],
            &[[-4.0, 5.5, -6.0, 0.25], [7.0, 8.0, 9.0, 1.0]],
        ];
        let (read, datatype_id) = raw_cloud_points(&cloud(2, 2, &rows)).unwrap();
        assert_eq!(datatype_id, Some(datatype::FLOAT32));
        assert_eq!(read.dropped, 1);
        assert_eq!(
            read.points,
            [
                [1.0, 2.0, 3.0, 0.5],
                [-4.0, 5.5, -6.0, 0.25],
                [7.0, 8.0, 9.0, 1.0]
            ]
        );
    }

    #[test]
    fn the_common_layouts_reading_agrees_with_the_general_one() {
        // A NaN and an Ouster-style beam without a return (the origin) in each.
        let rows: [&[[f32; 4]]; 2] = [
            &[[1.5, -2.0, 3.0, 0.5], [0.0, f32::INFINITY, 0.0, 0.1]],
            &[[-4.0, 5.5, -6.0, 0.25], [0.0, 0.0, 0.0, 0.0]],
        ];
        let common = cloud(2, 2, &rows);
        // A label field (the padding bytes) sends the same points the general way.
        let mut labelled = common.clone();
        (labelled.fields).push(PointField::scalar("label", 16, datatype::UINT32));
        let (fast, _) = raw_cloud_points(&common).unwrap();
        let (general, _) = raw_cloud_points(&labelled).unwrap();
        assert_eq!(fast.points, general.points);
        assert_eq!(
            fast.points,
            [[1.5, -2.0, 3.0, 0.5], [-4.0, 5.5, -6.0, 0.25]]
        );
        assert_eq!((fast.dropped, general.dropped), (2, 2));
        assert_eq!(general.labels, Some(vec![0xABAB_ABAB; 2]));
        // Without an intensity field, intensity 0.
        let mut bare = common.clone();
        bare.fields.truncate(3);
        let (bare, datatype_id) = raw_cloud_points(&bare).unwrap();
        assert_eq!(datatype_id, None);
        assert!(
            bare.points
                .iter()
                .zip(&fast.points)
                .all(|(b, f)| b[..3] == f[..3] && b[3] == 0.0)
        );
    }

    #[test]
    fn an_ouster_clouds_reflectivity_is_its_remission() {
        // ouster_ros's point: x, y, z, intensity (the photon count) float32, then
        // reflectivity uint16 (the calibrated 0..255).
        let mut ouster = cloud(2, 1, &[&[[1.0, 2.0, 3.0, 3000.0], [4.0, 5.0, 6.0, 700.0]]]);
        ouster
            .fields
            .push(PointField::scalar("reflectivity", 16, datatype::UINT16));
        let reflectivity = [51u16, 255];
        for (point, value) in ouster.data.chunks_mut(20).zip(reflectivity) {
            point[16..18].copy_from_slice(&value.to_le_bytes());
        }
        let read = cloud_points(&ouster).unwrap();
        assert_eq!(read.remission, RemissionScale::Byte);
        let byte = 1.0f32 / 255.0;
        assert_eq!(
            read.points,
            [[1.0, 2.0, 3.0, 51.0 * byte], [4.0, 5.0, 6.0, 255.0 * byte]]
        );
        // A uint16 field past 255 is on a scale travmap does not know.
        (ouster.data[36..38]).copy_from_slice(&256u16.to_le_bytes());
        assert_eq!(
            cloud_points(&ouster).unwrap().remission,
            RemissionScale::Unknown
        );
    }

    #[test]
    fn rows_of_no_points_read_as_an_empty_cloud() {
        let (read, _) = raw_cloud_points(&cloud(0, 3, &[])).unwrap();
        assert!(read.points.is_empty() && read.dropped == 0);
    }

    #[test]
    fn clouds_whose_data_disagree_with_their_layout_are_errors() {
        use travmap_formats::ros::Header;
        let assert_contains = |text: &str, parts: &[&str]| {
            for part in parts {
                assert!(text.contains(part), "{part:?} not in: {text}");
            }
        };
        let cloud = |data_len: usize, fields: Vec<PointField>| PointCloud2 {
            header: Header::default(),
            height: 2,
            width: 3,
            fields,
            is_bigendian: false,
            point_step: 12,
            row_step: 36,
            // Small finite floats, none at the origin.
            data: (1..=data_len).map(|i| i as u8).collect(),
            is_dense: true,
        };
        let error = |data_len, fields| cloud_points(&cloud(data_len, fields)).err().unwrap();
        let err = error(60, PointField::xyz_float32());
        assert_contains(&err, &["data holds 60 bytes", "need 72"]);
        let err = error(72, vec![PointField::scalar("y", 4, datatype::FLOAT32)]);
        assert_contains(&err, &["no `x` field"]);
        let err = error(72, vec![PointField::scalar("x", 10, datatype::FLOAT32)]);
        assert_contains(&err, &["outside point_step"]);
        assert_eq!(
            cloud_points(&cloud(72, PointField::xyz_float32()))
                .unwrap()
                .points
                .len(),
            6
        );
        // A header that claims 4 billion points over 72 bytes: refused before any
        // allocation, which is bounded by the bytes present.
        let mut huge = cloud(72, PointField::xyz_float32());
        (huge.width, huge.height, huge.row_step) = (1 << 31, 1 << 31, 12 << 31);
        let err = cloud_points(&huge).err().unwrap();
        assert!(err.contains("data holds 72 bytes"), "{err}");
        // A header that claims no points over 72 bytes of them: the driver did not
        // fill it in; reading zero points would map an empty scene.
        let mut unfilled = cloud(72, PointField::xyz_float32());
        unfilled.width = 0;
        let err = cloud_points(&unfilled).err().unwrap();
        assert_contains(
            &err,
            &["width 0 x height 2", "data holds 72 bytes (6 points"],
        );
        // Every point NaN: nothing to map, said rather than scored as empty.
        let nan = f32::NAN.to_le_bytes().repeat(18);
        let points = cloud_points(&PointCloud2 {
            data: nan,
            ..cloud(72, PointField::xyz_float32())
        })
        .unwrap();
        let err = check_some_finite(points.points.len(), points.dropped)
            .err()
            .unwrap();
        assert_contains(&err, &["every one of its 6 points has a NaN"]);
    }
}
