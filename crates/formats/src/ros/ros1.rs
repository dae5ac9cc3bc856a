//! The ROS 1 wire format, read into the same serde types as ROS 2's CDR ([`crate::ros`]).
//!
//! ROS 1 serialises fields in order, little-endian, unaligned; strings and
//! variable-length arrays are a `uint32` length then the elements, fixed-length
//! arrays the elements alone. For the types travmap reads, the ROS 1 messages
//! (`schemas/ros1/`) differ from the ROS 2 ones in one place only: `std_msgs/Header`
//! starts with a `uint32 seq`, which ROS 2 dropped. So the deserializer reads and
//! drops that field when it meets a struct named `Header`, and everything downstream
//! (clouds, transforms, images) is shared. ROS 1 `time` is two `uint32`s where ROS 2
//! has an `int32` and a `uint32`: the same bytes up to the year 2038.

use serde::de::{self, DeserializeOwned, DeserializeSeed, SeqAccess, Visitor};

/// Decodes a ROS 1 message; the error says what failed.
pub fn decode<T: DeserializeOwned>(bytes: &[u8]) -> Result<T, String> {
    let mut deserializer = Deserializer { input: bytes };
    T::deserialize(&mut deserializer).map_err(|e| format!("ROS 1 decoding failed: {}", e.0))
}

#[derive(Debug)]
struct DecodeError(String);

impl std::fmt::Display for DecodeError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for DecodeError {}

impl de::Error for DecodeError {
    fn custom<T: std::fmt::Display>(message: T) -> Self {
        DecodeError(message.to_string())
    }
}

struct Deserializer<'de> {
    input: &'de [u8],
}

impl<'de> Deserializer<'de> {
    fn take(&mut self, n: usize) -> Result<&'de [u8], DecodeError> {
        if n > self.input.len() {
            return Err(DecodeError(format!(
                "{n} bytes needed, {} left",
                self.input.len()
            )));
        }
        let (head, tail) = self.input.split_at(n);
        self.input = tail;
        Ok(head)
    }

    fn bytes<const N: usize>(&mut self) -> Result<[u8; N], DecodeError> {
        let mut out = [0; N];
        out.copy_from_slice(self.take(N)?);
        Ok(out)
    }

    /// A `uint32` length, bounded by what is left: every element takes a byte at least.
    fn length(&mut self) -> Result<usize, DecodeError> {
        let length = u32::from_le_bytes(self.bytes()?) as usize;
        if length > self.input.len() {
            return Err(DecodeError(format!(
                "a length of {length} with {} bytes left",
                self.input.len()
            )));
        }
        Ok(length)
    }

    fn unsupported(what: &str) -> DecodeError {
        DecodeError(format!("{what} is not part of the ROS 1 format"))
    }
}

macro_rules! primitive {
    ($method:ident, $visit:ident, $type:ty) => {
        fn $method<V: Visitor<'de>>(self, visitor: V) -> Result<V::Value, DecodeError> {
            visitor.$visit(<$type>::from_le_bytes(self.bytes()?))
        }
    };
}

impl<'de> de::Deserializer<'de> for &mut Deserializer<'de> {
    type Error = DecodeError;

    primitive!(deserialize_i8, visit_i8, i8);
    primitive!(deserialize_i16, visit_i16, i16);
    primitive!(deserialize_i32, visit_i32, i32);
    primitive!(deserialize_i64, visit_i64, i64);
    primitive!(deserialize_u8, visit_u8, u8);
    primitive!(deserialize_u16, visit_u16, u16);
    primitive!(deserialize_u32, visit_u32, u32);
    primitive!(deserialize_u64, visit_u64, u64);
    primitive!(deserialize_f32, visit_f32, f32);
    primitive!(deserialize_f64, visit_f64, f64);

    fn deserialize_bool<V: Visitor<'de>>(self, visitor: V) -> Result<V::Value, DecodeError> {
        visitor.visit_bool(self.bytes::<1>()?[0] != 0)
    }

    fn deserialize_str<V: Visitor<'de>>(self, visitor: V) -> Result<V::Value, DecodeError> {
        let length = self.length()?;
        let text = std::str::from_utf8(self.take(length)?)
            .map_err(|e| DecodeError(format!("a string that is not UTF-8: {e}")))?;
        visitor.visit_borrowed_str(text)
    }

    fn deserialize_string<V: Visitor<'de>>(self, visitor: V) -> Result<V::Value, DecodeError> {
        self.deserialize_str(visitor)
    }

    fn deserialize_bytes<V: Visitor<'de>>(self, visitor: V) -> Result<V::Value, DecodeError> {
        let length = self.length()?;
        visitor.visit_borrowed_bytes(self.take(length)?)
    }

    fn deserialize_byte_buf<V: Visitor<'de>>(self, visitor: V) -> Result<V::Value, DecodeError> {
        self.deserialize_bytes(visitor)
    }

    fn deserialize_seq<V: Visitor<'de>>(self, visitor: V) -> Result<V::Value, DecodeError> {
        let left = self.length()?;
        visitor.visit_seq(Elements {
            deserializer: self,
            left,
        })
    }

    fn deserialize_tuple<V: Visitor<'de>>(
        self,
        left: usize,
        visitor: V,
    ) -> Result<V::Value, DecodeError> {
        visitor.visit_seq(Elements {
            deserializer: self,
            left,
        })
    }

    fn deserialize_tuple_struct<V: Visitor<'de>>(
        self,
        _name: &'static str,
        left: usize,
        visitor: V,
    ) -> Result<V::Value, DecodeError> {
        self.deserialize_tuple(left, visitor)
    }

    fn deserialize_struct<V: Visitor<'de>>(
        self,
        name: &'static str,
        fields: &'static [&'static str],
        visitor: V,
    ) -> Result<V::Value, DecodeError> {
        if name == "Header" {
            // `uint32 seq`: ROS 1 only.
            self.take(4)?;
        }
        self.deserialize_tuple(fields.len(), visitor)
    }

    fn deserialize_unit<V: Visitor<'de>>(self, visitor: V) -> Result<V::Value, DecodeError> {
        visitor.visit_unit()
    }

    fn deserialize_unit_struct<V: Visitor<'de>>(
        self,
        _name: &'static str,
        visitor: V,
    ) -> Result<V::Value, DecodeError> {
        visitor.visit_unit()
    }

    fn deserialize_newtype_struct<V: Visitor<'de>>(
        self,
        _name: &'static str,
        visitor: V,
    ) -> Result<V::Value, DecodeError> {
        visitor.visit_newtype_struct(self)
    }

    fn deserialize_any<V: Visitor<'de>>(self, _visitor: V) -> Result<V::Value, DecodeError> {
        Err(Deserializer::unsupported("a self-describing value"))
    }

    fn deserialize_char<V: Visitor<'de>>(self, _visitor: V) -> Result<V::Value, DecodeError> {
        Err(Deserializer::unsupported("a char"))
    }

    fn deserialize_option<V: Visitor<'de>>(self, _visitor: V) -> Result<V::Value, DecodeError> {
        Err(Deserializer::unsupported("an optional value"))
    }

    fn deserialize_map<V: Visitor<'de>>(self, _visitor: V) -> Result<V::Value, DecodeError> {
        Err(Deserializer::unsupported("a map"))
    }

    fn deserialize_enum<V: Visitor<'de>>(
        self,
        _name: &'static str,
        _variants: &'static [&'static str],
        _visitor: V,
    ) -> Result<V::Value, DecodeError> {
        Err(Deserializer::unsupported("an enum"))
    }

    fn deserialize_identifier<V: Visitor<'de>>(self, _visitor: V) -> Result<V::Value, DecodeError> {
        Err(Deserializer::unsupported("a field name"))
    }

    fn deserialize_ignored_any<V: Visitor<'de>>(
        self,
        _visitor: V,
    ) -> Result<V::Value, DecodeError> {
        Err(Deserializer::unsupported("a value of unknown type"))
    }

    fn is_human_readable(&self) -> bool {
        false
    }
}

/// The elements of an array or the fields of a struct, in order.
struct Elements<'a, 'de> {
    deserializer: &'a mut Deserializer<'de>,
    left: usize,
}

impl<'de> SeqAccess<'de> for Elements<'_, 'de> {
    type Error = DecodeError;

    fn next_element_seed<T: DeserializeSeed<'de>>(
        &mut self,
        seed: T,
    ) -> Result<Option<T::Value>, DecodeError> {
        if self.left == 0 {
            return Ok(None);
        }
        self.left -= 1;
        seed.deserialize(&mut *self.deserializer).map(Some)
    }

    fn size_hint(&self) -> Option<usize> {
        Some(self.left)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ros::{CameraInfo, PointCloud2, TfMessage};

    /// Little-endian ROS 1 bytes, written by hand from the `.msg` texts.
    struct Bytes(Vec<u8>);

    impl Bytes {
        fn u32(mut self, v: u32) -> Self {
            self.0.extend_from_slice(&v.to_le_bytes());
            self
        }
        fn f64(mut self, v: f64) -> Self {
            self.0.extend_from_slice(&v.to_le_bytes());
            self
        }
        fn u8(mut self, v: u8) -> Self {
            self.0.push(v);
            self
        }
        fn string(self, s: &str) -> Self {
            let mut out = self.u32(s.len() as u32);
            out.0.extend_from_slice(s.as_bytes());
            out
        }
        fn header(self, seq: u32, secs: u32, nsecs: u32, frame: &str) -> Self {
            self.u32(seq).u32(secs).u32(nsecs).string(frame)
        }
    }

    #[test]
    fn a_point_cloud_reads_past_the_header_sequence_number() {
        let bytes = Bytes(Vec::new())
            .header(7, 1_317_000_000, 500, "velodyne")
            .u32(1) // height
            .u32(2) // width
            .u32(1) // one field
            .string("x")
            .u32(0)
            .u8(7)
            .u32(1)
            .u8(0) // is_bigendian
            .u32(4)
            .u32(8)
            .u32(8) // data
            .f64(f64::from_le_bytes([0, 0, 128, 63, 0, 0, 0, 64]))
            .u8(1)
            .0;
        let cloud: PointCloud2 = decode(&bytes).unwrap();
        assert_eq!(cloud.header.frame_id, "velodyne");
        assert_eq!(cloud.header.stamp.to_ns(), 1_317_000_000_000_000_500);
        assert_eq!((cloud.height, cloud.width, cloud.point_step), (1, 2, 4));
        assert_eq!(cloud.fields[0].name, "x");
        assert_eq!(cloud.data, [0, 0, 128, 63, 0, 0, 0, 64]);
        assert!(cloud.is_dense);
    }

    #[test]
    fn camera_info_reads_its_fixed_arrays_without_lengths() {
        let mut bytes = Bytes(Vec::new())
            .header(0, 1, 2, "camera")
            .u32(370)
            .u32(1240)
            .string("plumb_bob")
            .u32(0); // D
        for i in 0..(9 + 9 + 12) {
            bytes = bytes.f64(i as f64);
        }
        let bytes = bytes.u32(1).u32(1).u32(0).u32(0).u32(0).u32(0).u8(0).0;
        let info: CameraInfo = decode(&bytes).unwrap();
        assert_eq!((info.width, info.height), (1240, 370));
        assert_eq!(info.k[8], 8.0);
        assert_eq!(info.p[11], 29.0);
        assert_eq!(info.binning_x, 1);
    }

    /// The claim this module rests on, checked against the `.msg` texts: with the
    /// Header's `seq` taken out, every ROS 1 type travmap reads has the ROS 2 fields,
    /// in the same order, of the same wire types.
    #[test]
    fn ros1_types_are_the_ros2_ones_but_for_the_header_sequence_number() {
        let dir =
            std::path::Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/../..")).join("schemas");
        for file in [
            "sensor_msgs__PointCloud2.msg",
            "sensor_msgs__CompressedImage.msg",
            "sensor_msgs__Image.msg",
            "sensor_msgs__CameraInfo.msg",
            "nav_msgs__Odometry.msg",
            "tf2_msgs__TFMessage.msg",
            "velodyne_msgs__VelodyneScan.msg",
            "pandar_msgs__PandarScan.msg",
            "livox_ros_driver2__CustomMsg.msg",
        ] {
            let fields = |path: std::path::PathBuf| -> Vec<String> {
                std::fs::read_to_string(&path)
                    .unwrap()
                    .lines()
                    .filter(|l| !l.starts_with("MSG:") && !l.starts_with("==="))
                    .filter(|l| !l.trim().is_empty() && !l.contains('='))
                    // ROS 2 spells out what ROS 1 keeps built in.
                    .map(|l| l.replace("builtin_interfaces/Time", "time").to_lowercase())
                    .filter(|l| l != "int32 sec" && l != "uint32 nanosec")
                    .collect()
            };
            let mut ros1 = fields(dir.join("ros1").join(file));
            let seq = ros1.iter().position(|l| l == "uint32 seq").unwrap();
            ros1.remove(seq);
            assert_eq!(ros1, fields(dir.join(file)), "{file}");
        }
    }

    #[test]
    fn truncated_and_lying_messages_are_errors() {
        let bytes = Bytes(Vec::new())
            .u32(1) // one transform
            .header(0, 1, 2, "map")
            .string("velodyne")
            .0;
        // The transform's seven float64s are missing.
        let err = decode::<TfMessage>(&bytes).unwrap_err();
        assert!(err.contains("bytes needed"), "{err}");
        let lying = Bytes(Vec::new()).u32(u32::MAX).0;
        let err = decode::<TfMessage>(&lying).unwrap_err();
        assert!(
            err.contains("a length of 4294967295 with 0 bytes left"),
            "{err}"
        );
    }
}
