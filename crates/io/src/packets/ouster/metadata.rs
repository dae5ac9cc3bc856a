//! The sensor's metadata JSON, as ouster_ros publishes it on `/ouster/metadata` and
//! the sensor serves it (`/api/v1/sensor/metadata`): firmware 2 and later nest it
//! (`beam_intrinsics`, `lidar_intrinsics`, `lidar_data_format`, `config_params`,
//! `sensor_info`), firmware 1 and the SDK's older files keep it flat
//! (`beam_altitude_angles`, `data_format`, ...). Either is read.

use nalgebra::Matrix4;
use serde_json::Value;
use travmap_formats::ros::MessageEncoding;

use super::packet::{OusterModel, Profile};

/// What decoding a sensor's packets takes: their layout and the beams' geometry.
#[derive(Clone, Debug, PartialEq)]
pub struct OusterMetadata {
    pub model: OusterModel,
    /// `prod_line`, e.g. `OS-1-64`.
    pub product: String,
    /// The first and last measurement ids the sensor sends (inclusive; the last is
    /// below the first when the window wraps past column 0).
    pub column_window: (u16, u16),
    pub beam_altitude_deg: Vec<f64>,
    pub beam_azimuth_deg: Vec<f64>,
    /// The beams' origin in the lidar frame, millimetres.
    pub beam_to_lidar_mm: Matrix4<f64>,
    /// The lidar frame in the sensor frame (a half turn about z and the window's
    /// height on an OS1), millimetres.
    pub lidar_to_sensor_mm: Matrix4<f64>,
}

impl OusterMetadata {
    /// The metadata a log recorded as a `std_msgs/String` message (ouster-ros's
    /// `/metadata` topic).
    pub fn from_message(data: &[u8], encoding: MessageEncoding) -> Result<Self, String> {
        Self::from_json(&string_message(data, encoding)?)
    }

    pub fn from_json(text: &str) -> Result<Self, String> {
        let root: Value =
            serde_json::from_str(text).map_err(|e| format!("not Ouster metadata JSON: {e}"))?;
        // Nested (firmware 2+) or flat (firmware 1): each value is looked up in its
        // section, then at the top.
        let find = |section: &str, key: &str| -> Option<&Value> {
            root.get(section)
                .and_then(|s| s.get(key))
                .or_else(|| root.get(key))
        };
        // Firmware before 1.14 gives no data format (or, asked through a newer
        // client, an error string in its place): its packets are LEGACY, 16 columns
        // each, a pixel per beam angle, and its lidar mode says the columns a turn.
        let no_format = serde_json::Map::new();
        let format = (root.get("lidar_data_format"))
            .or_else(|| root.get("data_format"))
            .and_then(Value::as_object)
            .unwrap_or(&no_format);
        let firmware_1 = format.is_empty();
        let from_mode = |key: &str| -> Option<u64> {
            let mode = find("config_params", "lidar_mode")?.as_str()?;
            match key {
                "columns_per_frame" => mode.split_once('x')?.0.parse().ok(),
                "columns_per_packet" => Some(16),
                _ => Some(
                    find("beam_intrinsics", "beam_altitude_angles")?
                        .as_array()?
                        .len() as u64,
                ),
            }
        };
        let count = |key: &str| -> Result<u16, String> {
            let value = match firmware_1 {
                false => format.get(key).and_then(Value::as_u64),
                true => from_mode(key),
            };
            let value = value.ok_or_else(|| match firmware_1 {
                false => format!("no whole `{key}` in the data format"),
                true => "no data format, nor a `lidar_mode` and beam angles to tell it from: not Ouster sensor metadata".to_string(),
            })?;
            u16::try_from(value).map_err(|_| format!("`{key}` {value} is out of range"))
        };
        let pixels_per_column = count("pixels_per_column")?;
        let columns_per_packet = count("columns_per_packet")?;
        let columns_per_frame = count("columns_per_frame")?;
        // Firmware before 2.2 streams LEGACY packets and names no profile.
        let profile = match format
            .get("udp_profile_lidar")
            .or_else(|| find("config_params", "udp_profile_lidar"))
        {
            None | Some(Value::Null) => Profile::Legacy,
            Some(name) => Profile::from_name(name.as_str().unwrap_or_default())?,
        };
        let header = format.get("header_type").and_then(Value::as_str);
        let expected = if profile.is_fusa() {
            "FUSA"
        } else {
            "STANDARD"
        };
        if let Some(header) = header.filter(|h| *h != expected) {
            return Err(format!(
                "packet header type {header} with profile {}: travmap reads the {expected} header with it",
                profile.name()
            ));
        }
        // Ouster's sensors have 16 to 128 beams and 512 to 4,096 columns a turn.
        if !(1..=128).contains(&pixels_per_column) {
            return Err(format!(
                "{pixels_per_column} pixels per column (at most 128)"
            ));
        }
        if !(1..=4096).contains(&columns_per_frame)
            || !(1..=columns_per_frame).contains(&columns_per_packet)
        {
            return Err(format!(
                "{columns_per_packet} columns per packet of {columns_per_frame} per frame"
            ));
        }
        let column_window = match format.get("column_window").and_then(Value::as_array) {
            None => (0, columns_per_frame - 1),
            Some(ends) => match ends.as_slice() {
                [first, last] => {
                    let end = |v: &Value| {
                        (v.as_u64().and_then(|v| u16::try_from(v).ok()))
                            .filter(|&v| v < columns_per_frame)
                    };
                    end(first).zip(end(last)).ok_or_else(|| {
                        format!("column window {ends:?} outside 0..{columns_per_frame}")
                    })?
                }
                _ => return Err(format!("column window {ends:?}: two columns expected")),
            },
        };
        let numbers = |section: &str, key: &str, len: usize| -> Result<Vec<f64>, String> {
            let values = find(section, key)
                .and_then(Value::as_array)
                .ok_or_else(|| format!("no `{key}`"))?;
            let numbers: Vec<f64> = values.iter().filter_map(Value::as_f64).collect();
            if numbers.len() != values.len() || numbers.len() != len {
                return Err(format!(
                    "`{key}` has {} values, {len} numbers expected",
                    values.len()
                ));
            }
            match numbers.iter().all(|v| v.is_finite()) {
                true => Ok(numbers),
                false => Err(format!("`{key}` is not finite")),
            }
        };
        let product_line = find("sensor_info", "prod_line").and_then(Value::as_str);
        let h = usize::from(pixels_per_column);
        let beam_altitude_deg = numbers("beam_intrinsics", "beam_altitude_angles", h)?;
        let beam_azimuth_deg = numbers("beam_intrinsics", "beam_azimuth_angles", h)?;
        let matrix = |values: Vec<f64>| Matrix4::from_row_slice(&values);
        let beam_to_lidar_mm = match find("beam_intrinsics", "beam_to_lidar_transform") {
            Some(_) => matrix(numbers("beam_intrinsics", "beam_to_lidar_transform", 16)?),
            // Before it was given whole, the beams sat on the x axis; before firmware
            // 2.0 not even that distance was given: the product line's (the SDK's).
            None => {
                let origin = match find("beam_intrinsics", "lidar_origin_to_beam_origin_mm") {
                    Some(origin) => (origin.as_f64())
                        .filter(|v| v.is_finite())
                        .ok_or("`lidar_origin_to_beam_origin_mm` is not a number")?,
                    None => default_beam_origin_mm(product_line),
                };
                let mut m = Matrix4::identity();
                m[(0, 3)] = origin;
                m
            }
        };
        let lidar_to_sensor_mm = matrix(numbers(
            "lidar_intrinsics",
            "lidar_to_sensor_transform",
            16,
        )?);
        let product = product_line.unwrap_or("Ouster").to_string();
        Ok(Self {
            model: OusterModel {
                profile,
                pixels_per_column,
                columns_per_packet,
                columns_per_frame,
            },
            product,
            column_window,
            beam_altitude_deg,
            beam_azimuth_deg,
            beam_to_lidar_mm,
            lidar_to_sensor_mm,
        })
    }

    /// Each beam's direction and origin in the sensor frame at each measurement id
    /// (index `id * pixels_per_column + beam`), metres, by the sensor
    /// documentation's formula (the SDK's `XYZLut`): a point is `origin + range *
    /// direction`.
    pub fn beams(&self) -> (Vec<[f32; 3]>, Vec<[f32; 3]>) {
        let (h, w) = (
            usize::from(self.model.pixels_per_column),
            usize::from(self.model.columns_per_frame),
        );
        let (rotation, translation) = (
            self.lidar_to_sensor_mm.fixed_view::<3, 3>(0, 0),
            self.lidar_to_sensor_mm.fixed_view::<3, 1>(0, 3),
        );
        let (beam_x, beam_z) = (self.beam_to_lidar_mm[(0, 3)], self.beam_to_lidar_mm[(2, 3)]);
        let origin_distance = beam_x.hypot(beam_z);
        let mut directions = Vec::with_capacity(h * w);
        let mut origins = Vec::with_capacity(h * w);
        for id in 0..w {
            let encoder = std::f64::consts::TAU * (1.0 - id as f64 / w as f64);
            for beam in 0..h {
                let azimuth = -self.beam_azimuth_deg[beam].to_radians();
                let altitude = self.beam_altitude_deg[beam].to_radians();
                let direction = nalgebra::Vector3::new(
                    (encoder + azimuth).cos() * altitude.cos(),
                    (encoder + azimuth).sin() * altitude.cos(),
                    altitude.sin(),
                );
                let origin =
                    nalgebra::Vector3::new(beam_x * encoder.cos(), beam_x * encoder.sin(), beam_z)
                        - direction * origin_distance;
                let direction = rotation * direction;
                let origin = (rotation * origin + translation) / 1000.0;
                directions.push(direction.map(|v| v as f32).into());
                origins.push(origin.map(|v| v as f32).into());
            }
        }
        (directions, origins)
    }
}

/// The distance of the beams' origin from the lidar's axis by product line, for
/// metadata that does not give it (firmware before 2.0), as ouster-sdk assumes it.
fn default_beam_origin_mm(product_line: Option<&str>) -> f64 {
    let line = product_line.unwrap_or_default();
    if line.starts_with("OS-0") || line.starts_with("OS0") {
        27.67
    } else if line.starts_with("OS-1") || line.starts_with("OS1") {
        15.806
    } else if line.starts_with("OS-2") || line.starts_with("OS2") {
        13.762
    } else {
        12.163
    }
}

/// The text of a `std_msgs/String` message.
pub fn string_message(data: &[u8], encoding: MessageEncoding) -> Result<String, String> {
    #[derive(serde::Deserialize)]
    struct StringMessage {
        data: String,
    }
    let message: StringMessage = encoding.decode(data)?;
    Ok(message.data)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An OS1-64's metadata as firmware 2 nests it (the SDK's default intrinsics,
    /// abridged to four beams).
    pub(crate) fn nested(profile: &str) -> String {
        format!(
            r#"{{
            "beam_intrinsics": {{
                "beam_altitude_angles": [16.611, 5.5, -5.5, -16.611],
                "beam_azimuth_angles": [3.164, 1.055, -1.055, -3.164],
                "beam_to_lidar_transform": [1,0,0,15.806, 0,1,0,0, 0,0,1,0, 0,0,0,1],
                "lidar_origin_to_beam_origin_mm": 15.806
            }},
            "lidar_intrinsics": {{
                "lidar_to_sensor_transform": [-1,0,0,0, 0,-1,0,0, 0,0,1,36.18, 0,0,0,1]
            }},
            "lidar_data_format": {{
                "column_window": [0, 1023], "columns_per_frame": 1024,
                "columns_per_packet": 16, "pixels_per_column": 4,
                "udp_profile_lidar": "{profile}"
            }},
            "config_params": {{"lidar_mode": "1024x10", "udp_profile_lidar": "{profile}"}},
            "sensor_info": {{"prod_line": "OS-1-64"}}
        }}"#
        )
    }

    #[test]
    fn nested_and_flat_metadata_read_the_same() {
        let nested = OusterMetadata::from_json(&nested("RNG19_RFL8_SIG16_NIR16")).unwrap();
        assert_eq!(nested.model.profile, Profile::Rng19Rfl8Sig16Nir16);
        assert_eq!(nested.product, "OS-1-64");
        assert_eq!(nested.column_window, (0, 1023));
        let flat = r#"{
            "beam_altitude_angles": [16.611, 5.5, -5.5, -16.611],
            "beam_azimuth_angles": [3.164, 1.055, -1.055, -3.164],
            "lidar_origin_to_beam_origin_mm": 15.806,
            "lidar_to_sensor_transform": [-1,0,0,0, 0,-1,0,0, 0,0,1,36.18, 0,0,0,1],
            "data_format": {"columns_per_frame": 1024, "columns_per_packet": 16,
                            "pixels_per_column": 4, "udp_profile_lidar": "RNG19_RFL8_SIG16_NIR16"},
            "prod_line": "OS-1-64"
        }"#;
        assert_eq!(OusterMetadata::from_json(flat).unwrap(), nested);
        // Firmware 1 names no profile: its packets are LEGACY.
        let legacy = flat.replace(r#", "udp_profile_lidar": "RNG19_RFL8_SIG16_NIR16""#, "");
        let legacy = OusterMetadata::from_json(&legacy).unwrap();
        assert_eq!(legacy.model.profile, Profile::Legacy);
    }

    #[test]
    fn a_beam_points_where_the_documentation_says() {
        let metadata = OusterMetadata::from_json(&nested("LEGACY")).unwrap();
        let (directions, origins) = metadata.beams();
        // Measurement id 0 looks along the lidar frame's +x, which the half turn
        // makes the sensor frame's -x; beam 1 at 5.5 degrees up, 1.055 degrees off.
        let (d, o) = (directions[1], origins[1]);
        let (alt, az) = (5.5f64.to_radians(), (-1.055f64).to_radians());
        let expected = [-(az.cos() * alt.cos()), -(az.sin() * alt.cos()), alt.sin()];
        for k in 0..3 {
            assert!(
                (f64::from(d[k]) - expected[k]).abs() < 1e-6,
                "{d:?} {expected:?}"
            );
        }
        // The beam's origin: 15.806 mm out along +x (-x in the sensor frame), less
        // its own length along the beam, 36.18 mm up.
        let r = 0.015806;
        let origin = [
            -r - r * expected[0],
            -r * expected[1],
            0.03618 - r * expected[2],
        ];
        for k in 0..3 {
            assert!(
                (f64::from(o[k]) - origin[k]).abs() < 1e-6,
                "{o:?} {origin:?}"
            );
        }
        // A quarter turn later (id 256 of 1024) the encoder has turned -90 degrees.
        let quarter = directions[256 * 4 + 1];
        assert!((f64::from(quarter[1]) - az.cos() * alt.cos()).abs() < 1e-6);
    }

    #[test]
    fn bad_metadata_is_refused_with_what_is_wrong() {
        let problem = |text: &str| OusterMetadata::from_json(text).unwrap_err();
        assert!(problem("{}").contains("not Ouster sensor metadata"));
        assert!(problem("not json").contains("not Ouster metadata JSON"));
        let five_beams =
            nested("LEGACY").replace("\"pixels_per_column\": 4", "\"pixels_per_column\": 5");
        assert!(problem(&five_beams).contains("`beam_altitude_angles` has 4 values, 5"));
        let unknown = problem(&nested("RNG99"));
        for said in [
            "RNG99",
            "RNG15_RFL8_NIR8_DUAL",
            "FUSA_RNG15_RFL8_NIR8_DUAL",
            "RNG19_RFL8_SIG16_NIR16_DUAL",
        ] {
            assert!(unknown.contains(said), "{unknown}");
        }
        let window = nested("LEGACY").replace("[0, 1023]", "[0, 1024]");
        assert!(problem(&window).contains("column window"));
        let fusa = nested("LEGACY").replace(
            "\"columns_per_packet\": 16",
            "\"columns_per_packet\": 16, \"header_type\": \"FUSA\"",
        );
        assert!(problem(&fusa).contains("FUSA"));
        let fusa = nested("FUSA_RNG15_RFL8_NIR8_DUAL").replace(
            "\"columns_per_packet\": 16",
            "\"columns_per_packet\": 16, \"header_type\": \"FUSA\"",
        );
        assert!(
            OusterMetadata::from_json(&fusa)
                .unwrap()
                .model
                .profile
                .is_fusa()
        );
    }
}
