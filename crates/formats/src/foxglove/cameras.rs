//! Foxglove's cameras: `foxglove.CompressedImage`, `foxglove.RawImage` and
//! `foxglove.CameraCalibration`.

use super::basics::{each_field, timestamp};
use crate::ros::{CameraInfo, CompressedImage, Header, Image, RegionOfInterest};

pub(super) fn compressed_image(message: &[u8], whole: bool) -> Result<CompressedImage, String> {
    let mut image = CompressedImage {
        header: Header::default(),
        format: String::new(),
        data: Vec::new(),
    };
    each_field(message, |n, value| {
        match n {
            1 => image.header.stamp = timestamp(value.bytes(n)?)?,
            2 if whole => image.data = value.bytes(n)?.to_vec(),
            3 => image.format = value.string(n)?,
            4 => image.header.frame_id = value.string(n)?,
            _ => {}
        }
        Ok(())
    })?;
    Ok(image)
}

pub(super) fn raw_image(message: &[u8], whole: bool) -> Result<Image, String> {
    let mut image = Image {
        header: Header::default(),
        height: 0,
        width: 0,
        encoding: String::new(),
        is_bigendian: 0,
        step: 0,
        data: Vec::new(),
    };
    each_field(message, |n, value| {
        match n {
            1 => image.header.stamp = timestamp(value.bytes(n)?)?,
            2 => image.width = value.fixed32(n)?,
            3 => image.height = value.fixed32(n)?,
            4 => image.encoding = value.string(n)?,
            5 => image.step = value.fixed32(n)?,
            6 if whole => image.data = value.bytes(n)?.to_vec(),
            7 => image.header.frame_id = value.string(n)?,
            _ => {}
        }
        Ok(())
    })?;
    Ok(image)
}

/// `foxglove.CameraCalibration` as read, in either encoding.
#[derive(Default)]
pub(super) struct Calibration {
    pub header: Header,
    pub width: u32,
    pub height: u32,
    pub model: String,
    pub d: Vec<f64>,
    pub k: Vec<f64>,
    pub r: Vec<f64>,
    pub p: Vec<f64>,
}

/// `foxglove.CameraCalibration` in protobuf.
pub(super) fn camera_calibration(message: &[u8]) -> Result<CameraInfo, String> {
    let mut c = Calibration::default();
    each_field(message, |n, value| {
        match n {
            1 => c.header.stamp = timestamp(value.bytes(n)?)?,
            2 => c.width = value.fixed32(n)?,
            3 => c.height = value.fixed32(n)?,
            4 => c.model = value.string(n)?,
            5 => value.doubles(n, &mut c.d)?,
            6 => value.doubles(n, &mut c.k)?,
            7 => value.doubles(n, &mut c.r)?,
            8 => value.doubles(n, &mut c.p)?,
            9 => c.header.frame_id = value.string(n)?,
            _ => {}
        }
        Ok(())
    })?;
    c.camera_info()
}

impl Calibration {
    /// As a CameraInfo: Foxglove's `kannala_brandt` is ROS's `equidistant` (OpenCV's
    /// fisheye model); without R, none; without P, K's `[K | 0]`.
    pub(super) fn camera_info(self) -> Result<CameraInfo, String> {
        let Calibration {
            header,
            width,
            height,
            mut model,
            d,
            k,
            r,
            p,
        } = self;
        if model == "kannala_brandt" {
            model = "equidistant".into();
        }
        let k: [f64; 9] = k
            .try_into()
            .map_err(|k: Vec<f64>| format!("K of {} values (9 expected)", k.len()))?;
        let r: [f64; 9] = match r.len() {
            0 => [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
            _ => r
                .try_into()
                .map_err(|r: Vec<f64>| format!("R of {} values (9 expected)", r.len()))?,
        };
        let p: [f64; 12] = match p.len() {
            0 => [
                k[0], k[1], k[2], 0.0, k[3], k[4], k[5], 0.0, k[6], k[7], k[8], 0.0,
            ],
            _ => p
                .try_into()
                .map_err(|p: Vec<f64>| format!("P of {} values (12 expected)", p.len()))?,
        };
        Ok(CameraInfo {
            header,
            height,
            width,
            distortion_model: model,
            d,
            k,
            r,
            p,
            binning_x: 0,
            binning_y: 0,
            roi: RegionOfInterest::default(),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::super::basics::wire::*;
    use super::*;

    #[test]
    fn cameras_read_as_ros_images_and_camera_infos() {
        // CompressedImage numbers frame_id after the data.
        let image = message(|m| {
            bytes(1, &stamp(3, 500), m);
            bytes(2, b"\x89PNG...", m);
            bytes(3, b"png", m);
            bytes(4, b"camera", m);
        });
        let read = compressed_image(&image, true).unwrap();
        assert_eq!(
            (read.header.frame_id.as_str(), read.format.as_str()),
            ("camera", "png")
        );
        assert_eq!(read.data, b"\x89PNG...");
        let header = compressed_image(&image, false).unwrap();
        assert_eq!((header.header, header.data.len()), (read.header, 0));
        let raw = message(|m| {
            fixed32(2, 2, m);
            fixed32(3, 1, m);
            bytes(4, b"rgb8", m);
            fixed32(5, 6, m);
            bytes(6, &[1, 2, 3, 4, 5, 6], m);
            bytes(7, b"camera", m);
        });
        let read = raw_image(&raw, true).unwrap();
        assert_eq!(
            (read.width, read.height, read.step, read.encoding.as_str()),
            (2, 1, 6, "rgb8")
        );
        assert_eq!(read.data, [1, 2, 3, 4, 5, 6]);
        let k = [500.0, 0.0, 320.0, 0.0, 500.0, 240.0, 0.0, 0.0, 1.0];
        let calibration = |k: &[f64]| {
            message(|m| {
                fixed32(2, 640, m);
                fixed32(3, 480, m);
                bytes(4, b"kannala_brandt", m);
                bytes(
                    5,
                    &message(|d| {
                        [0.1f64, 0.0, 0.0, 0.0]
                            .iter()
                            .for_each(|v| d.extend(v.to_le_bytes()))
                    }),
                    m,
                );
                k.iter().for_each(|v| double(6, *v, m));
                bytes(9, b"camera", m);
            })
        };
        let read = camera_calibration(&calibration(&k)).unwrap();
        assert_eq!(
            (read.width, read.height, read.distortion_model.as_str()),
            (640, 480, "equidistant")
        );
        assert_eq!((read.d, read.k), (vec![0.1, 0.0, 0.0, 0.0], k));
        assert_eq!(
            read.r,
            [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
            "no R: none"
        );
        assert_eq!(
            read.p,
            [
                500.0, 0.0, 320.0, 0.0, 0.0, 500.0, 240.0, 0.0, 0.0, 0.0, 1.0, 0.0
            ]
        );
        let short = camera_calibration(&calibration(&k[..4]));
        assert_eq!(short.unwrap_err(), "K of 4 values (9 expected)");
    }
}
