//! Foxglove's schemas in JSON (`json` messages of `jsonschema` schemas, as the MCAP
//! examples and hand-made loggers write them): the protobuf messages' fields by name,
//! times as `{"sec", "nsec"}`, bytes in base64, a point field's type by number or name.

use serde::Deserialize;
use serde::de::DeserializeOwned;

use super::basics::{odometry_of, time};
use super::cameras::Calibration;
use super::point_cloud::{finish, numeric_type};
use crate::ros::{
    CompressedImage, Header, Image, PointCloud2, PointField, Pose, PoseStamped, Quaternion,
    TfMessage, Time, Transform, TransformStamped, Vector3, encode,
};

#[derive(Default, Deserialize)]
#[serde(default)]
struct Timestamp {
    sec: i64,
    nsec: i64,
}

/// A Header of a stamp and a frame.
fn header(stamp: &Timestamp, frame_id: String) -> Result<Header, String> {
    let stamp: Time = time(stamp.sec, stamp.nsec)?;
    Ok(Header { stamp, frame_id })
}

#[derive(Default, Deserialize)]
#[serde(default)]
struct Xyz {
    x: f64,
    y: f64,
    z: f64,
}

impl Xyz {
    fn vector(&self) -> Vector3 {
        Vector3 {
            x: self.x,
            y: self.y,
            z: self.z,
        }
    }
}

/// A quaternion as written: absent components are 0.
#[derive(Default, Deserialize)]
#[serde(default)]
struct Rotation {
    x: f64,
    y: f64,
    z: f64,
    w: f64,
}

/// None (not written) is no rotation.
fn rotation(rotation: &Option<Rotation>) -> Quaternion {
    rotation
        .as_ref()
        .map_or_else(Quaternion::default, |q| Quaternion {
            x: q.x,
            y: q.y,
            z: q.z,
            w: q.w,
        })
}

#[derive(Default, Deserialize)]
#[serde(default)]
struct JsonPose {
    position: Xyz,
    orientation: Option<Rotation>,
}

impl JsonPose {
    fn pose(&self) -> Pose {
        Pose {
            position: self.position.vector(),
            orientation: rotation(&self.orientation),
        }
    }
}

/// A numeric type by its number or its name (`FLOAT32`).
#[derive(Deserialize)]
#[serde(untagged)]
enum NumericType {
    Number(u64),
    Name(String),
}

const TYPE_NAMES: [&str; 9] = [
    "UNKNOWN", "UINT8", "INT8", "UINT16", "INT16", "UINT32", "INT32", "FLOAT32", "FLOAT64",
];

#[derive(Deserialize)]
struct Field {
    name: String,
    #[serde(default)]
    offset: u32,
    #[serde(rename = "type")]
    kind: NumericType,
}

impl Field {
    fn point_field(&self) -> Result<Option<PointField>, String> {
        let number = match &self.kind {
            NumericType::Number(n) => *n,
            NumericType::Name(name) => (TYPE_NAMES.iter())
                .position(|t| t.eq_ignore_ascii_case(name))
                .ok_or_else(|| format!("a field's numeric type `{name}`"))?
                as u64,
        };
        let kind = numeric_type(number).map_err(|p| format!("field `{}`: {p}", self.name))?;
        Ok(kind.map(|datatype| PointField::scalar(&self.name, self.offset, datatype)))
    }
}

#[derive(Default, Deserialize)]
#[serde(default)]
struct PointCloud {
    timestamp: Timestamp,
    frame_id: String,
    pose: Option<JsonPose>,
    point_stride: u32,
    fields: Vec<Field>,
    data: String,
}

#[derive(Default, Deserialize)]
#[serde(default)]
struct FrameTransform {
    timestamp: Timestamp,
    parent_frame_id: String,
    child_frame_id: String,
    translation: Xyz,
    rotation: Option<Rotation>,
}

impl FrameTransform {
    fn transform(&self) -> Result<TransformStamped, String> {
        Ok(TransformStamped {
            header: header(&self.timestamp, self.parent_frame_id.clone())?,
            child_frame_id: self.child_frame_id.clone(),
            transform: Transform {
                translation: self.translation.vector(),
                rotation: rotation(&self.rotation),
            },
        })
    }
}

#[derive(Default, Deserialize)]
#[serde(default)]
struct FrameTransforms {
    transforms: Vec<FrameTransform>,
}

#[derive(Default, Deserialize)]
#[serde(default)]
struct JsonCompressedImage {
    timestamp: Timestamp,
    frame_id: String,
    data: String,
    format: String,
}

#[derive(Default, Deserialize)]
#[serde(default)]
struct RawImage {
    timestamp: Timestamp,
    frame_id: String,
    width: u32,
    height: u32,
    encoding: String,
    step: u32,
    data: String,
}

#[derive(Default, Deserialize)]
#[serde(default)]
struct CameraCalibration {
    timestamp: Timestamp,
    frame_id: String,
    width: u32,
    height: u32,
    distortion_model: String,
    #[serde(rename = "D")]
    d: Vec<f64>,
    #[serde(rename = "K")]
    k: Vec<f64>,
    #[serde(rename = "R")]
    r: Vec<f64>,
    #[serde(rename = "P")]
    p: Vec<f64>,
}

#[derive(Default, Deserialize)]
#[serde(default)]
struct Odometry {
    timestamp: Timestamp,
    frame_id: String,
    body_frame_id: String,
    pose: JsonPose,
}

#[derive(Default, Deserialize)]
#[serde(default)]
struct PoseInFrame {
    timestamp: Timestamp,
    frame_id: String,
    pose: JsonPose,
}

fn parse<T: DeserializeOwned>(data: &[u8]) -> Result<T, String> {
    serde_json::from_slice(data).map_err(|e| e.to_string())
}

/// `data`, a JSON message of the Foxglove schema `schema_name`, as the CDR bytes of
/// its ROS 2 equivalent; with `whole` false without its payload.
pub(super) fn to_cdr(schema_name: &str, data: &[u8], whole: bool) -> Result<Vec<u8>, String> {
    let payload = |text: &str| match whole {
        true => base64(text),
        false => Ok(Vec::new()),
    };
    Ok(match schema_name {
        "foxglove.PointCloud" => {
            let json: PointCloud = parse(data)?;
            // Decoded for the header too: its size is the cloud's width.
            let points = base64(&json.data)?;
            let mut fields = Vec::new();
            for field in &json.fields {
                fields.extend(field.point_field()?);
            }
            let cloud = PointCloud2 {
                header: header(&json.timestamp, json.frame_id)?,
                fields,
                point_step: json.point_stride,
                data: &points[..],
                ..PointCloud2::default()
            };
            finish(cloud, json.pose.map(|p| p.pose()), whole)?
        }
        "foxglove.FrameTransform" => {
            let json: FrameTransform = parse(data)?;
            encode(
                &TfMessage {
                    transforms: vec![json.transform()?],
                },
                256,
            )
        }
        "foxglove.FrameTransforms" => {
            let json: FrameTransforms = parse(data)?;
            let transforms = json.transforms.iter().map(FrameTransform::transform);
            encode(
                &TfMessage {
                    transforms: transforms.collect::<Result<_, _>>()?,
                },
                256,
            )
        }
        "foxglove.CompressedImage" => {
            let json: JsonCompressedImage = parse(data)?;
            let image = CompressedImage {
                header: header(&json.timestamp, json.frame_id)?,
                format: json.format,
                data: payload(&json.data)?,
            };
            encode(&image, image.data.len())
        }
        "foxglove.RawImage" => {
            let json: RawImage = parse(data)?;
            let image = Image {
                header: header(&json.timestamp, json.frame_id)?,
                height: json.height,
                width: json.width,
                encoding: json.encoding,
                is_bigendian: 0,
                step: json.step,
                data: payload(&json.data)?,
            };
            encode(&image, image.data.len())
        }
        "foxglove.CameraCalibration" => {
            let json: CameraCalibration = parse(data)?;
            let calibration = Calibration {
                header: header(&json.timestamp, json.frame_id)?,
                width: json.width,
                height: json.height,
                model: json.distortion_model,
                d: json.d,
                k: json.k,
                r: json.r,
                p: json.p,
            };
            encode(&calibration.camera_info()?, 512)
        }
        "foxglove.Odometry" => {
            let json: Odometry = parse(data)?;
            let header = header(&json.timestamp, json.frame_id)?;
            encode(
                &odometry_of(header, json.body_frame_id, json.pose.pose()),
                512,
            )
        }
        "foxglove.PoseInFrame" => {
            let json: PoseInFrame = parse(data)?;
            let stamped = PoseStamped {
                header: header(&json.timestamp, json.frame_id)?,
                pose: json.pose.pose(),
            };
            encode(&stamped, 128)
        }
        other => return Err(format!("{other} is not a schema travmap reads")),
    })
}

/// Standard base64 (RFC 4648 section 4), padded or not.
fn base64(text: &str) -> Result<Vec<u8>, String> {
    let digits = text.trim_end_matches('=').as_bytes();
    let mut out = Vec::with_capacity(digits.len() * 3 / 4);
    let (mut bits, mut held) = (0u32, 0u32);
    for (i, &c) in digits.iter().enumerate() {
        let value = match c {
            b'A'..=b'Z' => c - b'A',
            b'a'..=b'z' => c - b'a' + 26,
            b'0'..=b'9' => c - b'0' + 52,
            b'+' => 62,
            b'/' => 63,
            _ => return Err(format!("base64 data: byte {i} is {:?}", c as char)),
        };
        bits = bits << 6 | u32::from(value);
        held += 6;
        if held >= 8 {
            held -= 8;
            out.push((bits >> held) as u8);
        }
    }
    if digits.len() % 4 == 1 {
        return Err(format!("base64 data of {} digits", digits.len()));
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ros::{CameraInfo, Odometry, datatype, decode};

    fn read<T: DeserializeOwned>(schema: &str, json: &str) -> T {
        decode(&to_cdr(schema, json.as_bytes(), true).unwrap()).unwrap()
    }

    #[test]
    fn base64_reads_padded_and_unpadded_text() {
        assert_eq!(base64("TWFu").unwrap(), b"Man");
        assert_eq!(base64("TWE=").unwrap(), b"Ma");
        assert_eq!(base64("TQ").unwrap(), b"M");
        assert_eq!(base64("").unwrap(), b"");
        assert_eq!(base64("+/+/").unwrap(), [0xfb, 0xff, 0xbf]);
        assert_eq!(base64("TW-u").unwrap_err(), "base64 data: byte 2 is '-'");
        assert!(base64("TWFuT").is_err());
    }

    #[test]
    fn a_json_point_cloud_reads_as_its_pointcloud2() {
        // Two float32 points, x then y then z, at (1, 0, 0) and (0, 2, -1), in a
        // frame turned 90 degrees about z at (1, 2, 3): as the MCAP examples write.
        let mut points = Vec::new();
        for v in [1.0f32, 0.0, 0.0, 0.0, 2.0, -1.0] {
            points.extend(v.to_le_bytes());
        }
        let encoded: String = {
            const DIGITS: &[u8] =
                b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
            points
                .chunks(3)
                .flat_map(|c| {
                    let n = (c[0] as u32) << 16 | (c[1] as u32) << 8 | c[2] as u32;
                    (0..4).map(move |i| DIGITS[(n >> (18 - 6 * i) & 63) as usize] as char)
                })
                .collect()
        };
        let half = std::f64::consts::FRAC_1_SQRT_2;
        let json = format!(
            r#"{{"timestamp": {{"sec": 5, "nsec": 7}}, "frame_id": "lidar",
            "pose": {{"position": {{"x": 1, "y": 2, "z": 3}}, "orientation": {{"x": 0, "y": 0, "z": {half}, "w": {half}}}}},
            "point_stride": 12,
            "fields": [{{"name": "x", "offset": 0, "type": 7}}, {{"name": "y", "offset": 4, "type": "FLOAT32"}},
                       {{"name": "z", "offset": 8, "type": 7}}, {{"name": "unused", "type": 0}}],
            "data": "{encoded}"}}"#
        );
        let cloud: PointCloud2 = read("foxglove.PointCloud", &json);
        assert_eq!(cloud.header.stamp, Time { sec: 5, nanosec: 7 });
        assert_eq!(
            (cloud.width, cloud.point_step, cloud.fields.len()),
            (2, 12, 3)
        );
        assert!(cloud.fields.iter().all(|f| f.datatype == datatype::FLOAT32));
        let xyz: Vec<f32> = (cloud.data.chunks(4))
            .map(|b| f32::from_le_bytes(b.try_into().unwrap()))
            .collect();
        for (a, b) in xyz.iter().zip([1.0, 3.0, 3.0, -1.0, 2.0, 2.0]) {
            assert!((a - b).abs() < 1e-6, "{xyz:?}");
        }
        let header = to_cdr("foxglove.PointCloud", json.as_bytes(), false).unwrap();
        let header: PointCloud2 = decode(&header).unwrap();
        assert_eq!((header.width, header.data.len()), (2, 0));
    }

    #[test]
    fn json_transforms_cameras_and_odometry_read_as_ros_messages() {
        let tf: TfMessage = read(
            "foxglove.FrameTransforms",
            r#"{"transforms": [{"timestamp": {"sec": 9, "nsec": 0}, "parent_frame_id": "map",
            "child_frame_id": "base_link", "translation": {"x": 1, "y": -2, "z": 0.5}}]}"#,
        );
        let t = &tf.transforms[0];
        assert_eq!(
            (t.header.frame_id.as_str(), t.child_frame_id.as_str()),
            ("map", "base_link")
        );
        assert_eq!(
            t.transform.translation,
            Vector3 {
                x: 1.0,
                y: -2.0,
                z: 0.5
            }
        );
        assert_eq!(
            t.transform.rotation,
            Quaternion::default(),
            "no rotation written: none"
        );
        let image: CompressedImage = read(
            "foxglove.CompressedImage",
            r#"{"timestamp": {"sec": 1, "nsec": 2}, "frame_id": "camera", "format": "jpeg", "data": "TWFu"}"#,
        );
        assert_eq!(
            (image.header.frame_id.as_str(), &image.data[..]),
            ("camera", &b"Man"[..])
        );
        let info: CameraInfo = read(
            "foxglove.CameraCalibration",
            r#"{"frame_id": "camera", "width": 640, "height": 480, "distortion_model": "kannala_brandt",
            "D": [0.1, 0, 0, 0], "K": [500, 0, 320, 0, 500, 240, 0, 0, 1]}"#,
        );
        assert_eq!(
            (info.width, info.distortion_model.as_str()),
            (640, "equidistant")
        );
        assert_eq!(info.p[5], 500.0);
        let odometry: Odometry = read(
            "foxglove.Odometry",
            r#"{"frame_id": "odom", "body_frame_id": "base_link", "pose": {"position": {"x": 4, "y": 5, "z": 6}}}"#,
        );
        assert_eq!(odometry.child_frame_id, "base_link");
        let stamped: PoseStamped = read(
            "foxglove.PoseInFrame",
            r#"{"timestamp": {"sec": 4, "nsec": 2}, "frame_id": "map", "pose": {"position": {"x": 1, "y": 2, "z": 3}}}"#,
        );
        assert_eq!(
            (stamped.header.frame_id.as_str(), stamped.header.stamp.sec),
            ("map", 4)
        );
        assert_eq!(stamped.pose.position.y, 2.0);
        assert_eq!(
            odometry.pose.pose.position,
            Vector3 {
                x: 4.0,
                y: 5.0,
                z: 6.0
            }
        );
    }

    #[test]
    fn json_that_does_not_read_says_why() {
        let error = |schema: &str, json: &str| to_cdr(schema, json.as_bytes(), true).unwrap_err();
        assert!(error("foxglove.FrameTransform", "{").contains("EOF"));
        let late = r#"{"timestamp": {"sec": 1, "nsec": 1000000000}}"#;
        assert!(
            error("foxglove.FrameTransform", late).contains("a timestamp's nanos of 1000000000")
        );
        let strange = r#"{"fields": [{"name": "x", "type": "FLOAT16"}]}"#;
        assert!(error("foxglove.PointCloud", strange).contains("a field's numeric type `FLOAT16`"));
        let uneven = r#"{"point_stride": 16, "data": "TWFu"}"#;
        assert!(error("foxglove.PointCloud", uneven).contains("3 bytes of points of stride 16"));
        let short = r#"{"K": [1, 2, 3]}"#;
        assert_eq!(
            error("foxglove.CameraCalibration", short),
            "K of 3 values (9 expected)"
        );
    }
}
