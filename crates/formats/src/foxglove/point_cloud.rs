//! `foxglove.PointCloud`: one row of points, its fields numbered as Foxglove numbers
//! them, its `pose` applied.

use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion};

use super::basics::{each_field, pose, timestamp};
use crate::ros::{PointCloud2, PointField, Pose, datatype, encode};

/// The ROS datatype of a `foxglove.PackedElementField.NumericType`; None for
/// `UNKNOWN` (0), a field Foxglove's own viewers leave out.
pub(super) fn numeric_type(value: u64) -> Result<Option<u8>, String> {
    Ok(Some(match value {
        0 => return Ok(None),
        1 => datatype::UINT8,
        2 => datatype::INT8,
        3 => datatype::UINT16,
        4 => datatype::INT16,
        5 => datatype::UINT32,
        6 => datatype::INT32,
        7 => datatype::FLOAT32,
        8 => datatype::FLOAT64,
        other => return Err(format!("a field's numeric type {other} (1-8 are defined)")),
    }))
}

fn packed_element_field(message: &[u8]) -> Result<Option<PointField>, String> {
    let (mut name, mut offset, mut kind) = (String::new(), 0, 0);
    each_field(message, |n, value| {
        match n {
            1 => name = value.string(n)?,
            2 => offset = value.fixed32(n)?,
            3 => kind = value.varint(n)?,
            _ => {}
        }
        Ok(())
    })?;
    let kind = numeric_type(kind).map_err(|problem| format!("field `{name}`: {problem}"))?;
    Ok(kind.map(|datatype| PointField::scalar(&name, offset, datatype)))
}

/// `foxglove.PointCloud` as one row of points; its `pose` (where the points' origin
/// lies in `frame_id`) applied to x, y, z.
pub(super) fn point_cloud(message: &[u8], whole: bool) -> Result<Vec<u8>, String> {
    let mut cloud = PointCloud2::<&[u8]>::default();
    let mut origin = None;
    each_field(message, |n, value| {
        match n {
            1 => cloud.header.stamp = timestamp(value.bytes(n)?)?,
            2 => cloud.header.frame_id = value.string(n)?,
            3 => origin = Some(pose(value.bytes(n)?)?),
            4 => cloud.point_step = value.fixed32(n)?,
            5 => cloud.fields.extend(packed_element_field(value.bytes(n)?)?),
            6 => cloud.data = value.bytes(n)?,
            _ => {}
        }
        Ok(())
    })?;
    finish(cloud, origin, whole)
}

/// A Foxglove cloud as read (one row, its fields and stride set) as CDR bytes: its
/// size checked, its points moved by `origin`; with `whole` false, without them.
pub(super) fn finish(
    mut cloud: PointCloud2<&[u8]>,
    origin: Option<Pose>,
    whole: bool,
) -> Result<Vec<u8>, String> {
    let (bytes, step) = (cloud.data.len(), cloud.point_step as usize);
    if step == 0 && bytes > 0 || step > 0 && bytes % step != 0 {
        return Err(format!("{bytes} bytes of points of stride {step}"));
    }
    cloud.height = 1;
    cloud.width = u32::try_from(bytes.checked_div(step).unwrap_or(0))
        .map_err(|_| format!("{bytes} bytes of points"))?;
    cloud.row_step = u32::try_from(bytes).map_err(|_| format!("{bytes} bytes of points"))?;
    let moved = match origin {
        Some(origin) if whole && !is_identity(&origin) => moved_points(&cloud, &origin)?,
        _ => Vec::new(),
    };
    let data = match whole {
        true if !moved.is_empty() => &moved[..],
        true => cloud.data,
        false => &[],
    };
    Ok(encode(&PointCloud2 { data, ..cloud }, data.len() + 256))
}

fn is_identity(pose: &Pose) -> bool {
    let (p, q) = (pose.position, pose.orientation);
    let no_turn = q.x == 0.0 && q.y == 0.0 && q.z == 0.0;
    p.x == 0.0 && p.y == 0.0 && p.z == 0.0 && no_turn
}

/// The cloud's points with x, y, z moved by `origin` (float32 or float64 fields).
fn moved_points(cloud: &PointCloud2<&[u8]>, origin: &Pose) -> Result<Vec<u8>, String> {
    let q = origin.orientation;
    let rotation = nalgebra::Quaternion::new(q.w, q.x, q.y, q.z);
    let rotation = UnitQuaternion::try_new(rotation, 1e-9)
        .ok_or("a pose whose orientation is no rotation (a quaternion of length 0)")?;
    let p = origin.position;
    let frame_from_points = Isometry3::from_parts(Translation3::new(p.x, p.y, p.z), rotation);
    let field = |name: &str| cloud.fields.iter().find(|f| f.name == name);
    let (Some(x), Some(y), Some(z)) = (field("x"), field("y"), field("z")) else {
        return Err("a pose other than identity and no x, y, z fields to move".into());
    };
    let size = match x.datatype {
        datatype::FLOAT32 => 4,
        datatype::FLOAT64 => 8,
        _ => 0,
    };
    let step = cloud.point_step as usize;
    let fits = |f: &PointField| f.datatype == x.datatype && f.offset as usize + size <= step;
    if size == 0 || ![x, y, z].into_iter().all(fits) {
        return Err(
            "a pose other than identity needs x, y, z of one float type inside the stride".into(),
        );
    }
    let offsets = [x.offset, y.offset, z.offset].map(|o| o as usize);
    let mut data = cloud.data.to_vec();
    for point in data.chunks_exact_mut(step) {
        let read = |o: usize| match size {
            4 => f32::from_le_bytes(point[o..o + 4].try_into().unwrap()) as f64,
            _ => f64::from_le_bytes(point[o..o + 8].try_into().unwrap()),
        };
        let moved = frame_from_points * Point3::from(offsets.map(read));
        for (o, v) in offsets.into_iter().zip(moved.coords.iter()) {
            match size {
                4 => point[o..o + 4].copy_from_slice(&(*v as f32).to_le_bytes()),
                _ => point[o..o + 8].copy_from_slice(&v.to_le_bytes()),
            }
        }
    }
    Ok(data)
}

#[cfg(test)]
mod tests {
    use super::super::basics::wire::*;
    use super::*;
    use crate::ros::{Time, decode};

    fn field(name: &str, offset: u32, kind: u64) -> Vec<u8> {
        message(|m| {
            bytes(1, name.as_bytes(), m);
            if offset > 0 {
                fixed32(2, offset, m);
            }
            key(3, 0, m);
            varint(kind, m);
        })
    }
    /// Two points (x, y, z float32, intensity uint8) in `lidar`, at `origin`.
    fn cloud(origin: Option<Vec<u8>>) -> Vec<u8> {
        let mut points = Vec::new();
        for p in [[1.0f32, 0.0, 0.0], [0.0, 2.0, -1.0]] {
            p.iter().for_each(|v| points.extend(v.to_le_bytes()));
            points.extend([200, 0, 0, 0]);
        }
        message(|m| {
            bytes(1, &stamp(5, 7), m);
            bytes(2, b"lidar", m);
            if let Some(origin) = origin {
                bytes(3, &origin, m);
            }
            fixed32(4, 16, m);
            for (name, offset, kind) in
                [("x", 0, 7), ("y", 4, 7), ("z", 8, 7), ("intensity", 12, 1)]
            {
                bytes(5, &field(name, offset, kind), m);
            }
            bytes(6, &points, m);
        })
    }
    fn xyz(cloud: &PointCloud2) -> Vec<[f32; 3]> {
        let value = |p: &[u8], o: usize| f32::from_le_bytes(p[o..o + 4].try_into().unwrap());
        let points = cloud.data.chunks_exact(16);
        points
            .map(|p| [value(p, 0), value(p, 4), value(p, 8)])
            .collect()
    }

    #[test]
    fn a_point_cloud_reads_as_the_pointcloud2_of_its_points() {
        let cdr = point_cloud(&cloud(None), true).unwrap();
        let read: PointCloud2 = decode(&cdr).unwrap();
        assert_eq!(read.header.stamp, Time { sec: 5, nanosec: 7 });
        assert_eq!(read.header.frame_id, "lidar");
        assert_eq!(
            (read.height, read.width, read.point_step, read.row_step),
            (1, 2, 16, 32)
        );
        let types: Vec<(&str, u32, u8)> = (read.fields.iter())
            .map(|f| (f.name.as_str(), f.offset, f.datatype))
            .collect();
        // Foxglove numbers UINT8 1, ROS 2.
        let f32 = datatype::FLOAT32;
        assert_eq!(
            types,
            [
                ("x", 0, f32),
                ("y", 4, f32),
                ("z", 8, f32),
                ("intensity", 12, 2)
            ]
        );
        assert_eq!(xyz(&read), [[1.0, 0.0, 0.0], [0.0, 2.0, -1.0]]);
        assert_eq!(read.data[12], 200);
        // A pass after the header alone gets no points, but their count.
        let cdr = point_cloud(&cloud(None), false).unwrap();
        let header: PointCloud2 = decode(&cdr).unwrap();
        assert_eq!((header.width, header.data.len()), (2, 0));
    }

    #[test]
    fn a_point_clouds_pose_moves_its_points_into_its_frame() {
        // At (1, 2, 3), turned 90 degrees about z: x goes to y.
        let half = std::f64::consts::FRAC_1_SQRT_2;
        let turn = message(|m| {
            double(3, half, m);
            double(4, half, m);
        });
        let origin = message(|m| {
            bytes(1, &vector(1.0, 2.0, 3.0), m);
            bytes(2, &turn, m);
        });
        let cdr = point_cloud(&cloud(Some(origin)), true).unwrap();
        let read: PointCloud2 = decode(&cdr).unwrap();
        let expected = [[1.0, 3.0, 3.0], [-1.0, 2.0, 2.0]];
        for (p, e) in xyz(&read).iter().zip(expected) {
            assert!(p.iter().zip(e).all(|(a, b)| (a - b).abs() < 1e-6), "{p:?}");
        }
        assert_eq!(read.data[12], 200, "other fields stay");
        // An origin at zero with no orientation written is no move.
        let unmoved = point_cloud(&cloud(Some(Vec::new())), true);
        assert_eq!(
            xyz(&decode(&unmoved.unwrap()).unwrap()),
            [[1.0, 0.0, 0.0], [0.0, 2.0, -1.0]]
        );
    }

    #[test]
    fn point_clouds_that_do_not_read_say_why() {
        let error = |data: &[u8]| point_cloud(data, true).unwrap_err();
        let whole = cloud(None);
        assert!(error(&whole[..whole.len() - 3]).contains("bytes, 29 left in the message"));
        let uneven = message(|m| {
            fixed32(4, 16, m);
            bytes(6, &[0; 20], m);
        });
        assert!(error(&uneven).ends_with("20 bytes of points of stride 16"));
        let strange = message(|m| bytes(5, &field("x", 0, 9), m));
        assert!(error(&strange).contains("field `x`: a field's numeric type 9"));
    }
}
