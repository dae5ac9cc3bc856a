//! What every Foxglove schema is built from: `google.protobuf.Timestamp`,
//! `foxglove.Vector3`, `Quaternion` and `Pose`, and the loop over a message's fields.

use crate::protobuf::{Value, fields};
use crate::ros::{
    FixedArray, Header, Odometry, Pose, PoseWithCovariance, Quaternion, Time, Twist,
    TwistWithCovariance, Vector3,
};

/// For each field of `message`, `on_field(number, value)`.
pub(super) fn each_field<'a>(
    message: &'a [u8],
    mut on_field: impl FnMut(u32, Value<'a>) -> Result<(), String>,
) -> Result<(), String> {
    for field in fields(message) {
        let (number, value) = field?;
        on_field(number, value)?;
    }
    Ok(())
}

/// `google.protobuf.Timestamp`.
pub(super) fn timestamp(message: &[u8]) -> Result<Time, String> {
    let (mut seconds, mut nanos) = (0i64, 0i64);
    each_field(message, |n, v| {
        // int64 and int32 travel as two's complement varints.
        match n {
            1 => seconds = v.varint(n)? as i64,
            2 => nanos = v.varint(n)? as i64,
            _ => {}
        }
        Ok(())
    })?;
    time(seconds, nanos)
}

/// A time of whole seconds and nanoseconds (0 to 1e9 - 1), as ROS holds it.
pub(super) fn time(seconds: i64, nanos: i64) -> Result<Time, String> {
    if !(0..1_000_000_000).contains(&nanos) {
        return Err(format!("a timestamp's nanos of {nanos}"));
    }
    Ok(Time {
        sec: seconds.clamp(i32::MIN.into(), i32::MAX.into()) as i32,
        nanosec: nanos as u32,
    })
}

pub(super) fn vector3(message: &[u8]) -> Result<Vector3, String> {
    let mut v = Vector3::default();
    each_field(message, |n, value| {
        match n {
            1 => v.x = value.double(n)?,
            2 => v.y = value.double(n)?,
            3 => v.z = value.double(n)?,
            _ => {}
        }
        Ok(())
    })?;
    Ok(v)
}

/// A quaternion as written: every component absent is 0 (so an absent one is no
/// rotation only where the caller says so).
pub(super) fn quaternion(message: &[u8]) -> Result<Quaternion, String> {
    let mut q = Quaternion {
        w: 0.0,
        ..Quaternion::default()
    };
    each_field(message, |n, value| {
        match n {
            1 => q.x = value.double(n)?,
            2 => q.y = value.double(n)?,
            3 => q.z = value.double(n)?,
            4 => q.w = value.double(n)?,
            _ => {}
        }
        Ok(())
    })?;
    Ok(q)
}

/// `foxglove.Pose`; without an orientation, none.
pub(super) fn pose(message: &[u8]) -> Result<Pose, String> {
    let mut pose = Pose::default();
    each_field(message, |n, value| {
        match n {
            1 => pose.position = vector3(value.bytes(n)?)?,
            2 => pose.orientation = quaternion(value.bytes(n)?)?,
            _ => {}
        }
        Ok(())
    })?;
    Ok(pose)
}

/// Protobuf as proto3 writers write it, for the tests: fields in number order,
/// zeros left out.
/// `foxglove.Odometry`'s pose of `body_frame_id` as a ROS Odometry (no twist, no
/// covariance: Foxglove's are not read).
pub(super) fn odometry_of(header: Header, body_frame_id: String, pose: Pose) -> Odometry {
    let zero = Vector3::default();
    Odometry {
        header,
        child_frame_id: body_frame_id,
        pose: PoseWithCovariance {
            pose,
            covariance: FixedArray(vec![0.0; 36]),
        },
        twist: TwistWithCovariance {
            twist: Twist {
                linear: zero,
                angular: zero,
            },
            covariance: FixedArray(vec![0.0; 36]),
        },
    }
}

#[cfg(test)]
pub(super) mod wire {
    pub fn key(field: u32, wire: u8, out: &mut Vec<u8>) {
        varint(u64::from(field) << 3 | u64::from(wire), out);
    }
    pub fn varint(mut v: u64, out: &mut Vec<u8>) {
        while v >= 0x80 {
            out.push(v as u8 | 0x80);
            v >>= 7;
        }
        out.push(v as u8);
    }
    pub fn bytes(field: u32, value: &[u8], out: &mut Vec<u8>) {
        key(field, 2, out);
        varint(value.len() as u64, out);
        out.extend(value);
    }
    pub fn double(field: u32, value: f64, out: &mut Vec<u8>) {
        key(field, 1, out);
        out.extend(value.to_le_bytes());
    }
    pub fn fixed32(field: u32, value: u32, out: &mut Vec<u8>) {
        key(field, 5, out);
        out.extend(value.to_le_bytes());
    }
    pub fn message(write: impl FnOnce(&mut Vec<u8>)) -> Vec<u8> {
        let mut out = Vec::new();
        write(&mut out);
        out
    }
    pub fn stamp(seconds: u64, nanos: u64) -> Vec<u8> {
        message(|m| {
            key(1, 0, m);
            varint(seconds, m);
            key(2, 0, m);
            varint(nanos, m);
        })
    }
    pub fn vector(x: f64, y: f64, z: f64) -> Vec<u8> {
        message(|m| {
            [x, y, z]
                .iter()
                .zip(1..)
                .for_each(|(v, n)| double(n, *v, m))
        })
    }
}
