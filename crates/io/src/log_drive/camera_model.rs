//! How a log's camera images are projected into, from its CameraInfo and topic: a raw
//! image through its lens (`travmap_core::lens`), a rectified one through ROS's `P R`.

use travmap_core::lens::Distortion;
use travmap_formats::ros::CameraInfo;

/// How points of the camera's frame become pixels of its images.
#[derive(Clone, Debug)]
pub enum Projection {
    /// A raw image: the intrinsics K, through the lens when it distorts.
    Raw {
        k: nalgebra::Matrix3<f64>,
        distortion: Option<Distortion>,
    },
    /// A rectified image (`image_rect`, `image_rect_color`, ...: a topic with `rect`
    /// in its name, as image_proc names them): `P R`, ROS's projection of the
    /// rectified frame, no distortion.
    Rectified(nalgebra::Matrix4<f64>),
}

impl Projection {
    /// As `info` says for `topic`, and a notice when its lens is not one travmap
    /// models (then projected as a pinhole).
    pub fn of(topic: &str, info: &CameraInfo) -> (Self, Option<String>) {
        if topic.contains("rect") {
            let p = nalgebra::Matrix3x4::from_row_slice(&info.p);
            let r = nalgebra::Matrix3::from_row_slice(&info.r);
            let mut rotation = nalgebra::Matrix4::identity();
            rotation.fixed_view_mut::<3, 3>(0, 0).copy_from(&r);
            let mut projection = nalgebra::Matrix4::identity();
            projection.fixed_view_mut::<3, 4>(0, 0).copy_from(&p);
            return (Self::Rectified(projection * rotation), None);
        }
        let k = nalgebra::Matrix3::from_row_slice(&info.k);
        match Distortion::of_camera_info(&info.distortion_model, &info.d) {
            Ok(distortion) => (Self::Raw { k, distortion }, None),
            Err(problem) => (
                Self::Raw {
                    k,
                    distortion: None,
                },
                Some(format!(
                    "the CameraInfo of {topic}'s frame `{}` has {problem}: its images are projected as a pinhole camera's, without distortion",
                    info.header.frame_id
                )),
            ),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use travmap_core::frame::{CameraImage, RgbImage};

    fn info(model: &str, d: Vec<f64>) -> CameraInfo {
        CameraInfo {
            header: travmap_formats::ros::Header {
                frame_id: "cam".into(),
                ..Default::default()
            },
            height: 480,
            width: 640,
            distortion_model: model.into(),
            d,
            k: [500.0, 0.0, 320.0, 0.0, 500.0, 240.0, 0.0, 0.0, 1.0],
            // A rectified camera with other intrinsics, and R a quarter turn about z.
            r: [0.0, -1.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0],
            p: [
                400.0, 0.0, 300.0, 0.0, 0.0, 400.0, 200.0, 0.0, 0.0, 0.0, 1.0, 0.0,
            ],
            binning_x: 0,
            binning_y: 0,
            roi: Default::default(),
        }
    }

    /// The pixel of the camera-frame point `p` in a 640 x 480 image of `topic`.
    fn pixel(topic: &str, info: &CameraInfo, p: [f64; 3]) -> Option<[f64; 2]> {
        let image = RgbImage {
            width: 640,
            height: 480,
            rgb: vec![0; 640 * 480 * 3],
        };
        let camera = match Projection::of(topic, info).0 {
            Projection::Raw { k, distortion } => CameraImage::from_intrinsics(
                &k,
                distortion,
                &nalgebra::Isometry3::identity(),
                image,
            ),
            Projection::Rectified(projection) => {
                CameraImage::new(&projection, &nalgebra::Matrix4::identity(), image)
            }
        };
        camera.project(p)
    }

    #[test]
    fn raw_images_are_seen_through_the_lens_and_rectified_ones_through_p_r() {
        let lens = info("plumb_bob", vec![-0.3, 0.1, 0.001, -0.002, 0.05]);
        // Raw: K after the distortion (lens.rs works the normalised point by hand).
        let [u, v] = pixel("/camera/image_raw/compressed", &lens, [0.2, -0.1, 1.0]).unwrap();
        assert!((u - (320.0 + 500.0 * 0.19675125)).abs() < 1e-9, "{u}");
        assert!((v - (240.0 - 500.0 * 0.098375625)).abs() < 1e-9, "{v}");
        // Without distortion, the pinhole K: the same as before lenses were modelled.
        let pinhole = info("plumb_bob", vec![0.0; 5]);
        assert_eq!(
            pixel("/camera/image_raw", &pinhole, [0.2, -0.1, 1.0]),
            Some([420.0, 190.0])
        );
        // Rectified: R turns (0.2, -0.1, 1) to (0.1, 0.2, 1), then P.
        let [u, v] = pixel("/camera/image_rect_color", &lens, [0.2, -0.1, 1.0]).unwrap();
        assert!(
            (u - 340.0).abs() < 1e-9 && (v - 280.0).abs() < 1e-9,
            "{u} {v}"
        );
        // Behind the camera: nothing.
        assert_eq!(pixel("/camera/image_raw", &lens, [0.2, -0.1, -1.0]), None);
    }

    #[test]
    fn a_lens_travmap_does_not_model_is_a_pinhole_with_a_notice() {
        let odd = info("kannala_brandt", vec![0.1, 0.2]);
        let (projection, notice) = Projection::of("/camera/image_raw", &odd);
        assert!(matches!(
            projection,
            Projection::Raw {
                distortion: None,
                ..
            }
        ));
        let notice = notice.unwrap();
        assert!(
            notice.contains("/camera/image_raw's frame `cam`")
                && notice.contains("`kannala_brandt` with 2 coefficients")
                && notice.contains("without distortion"),
            "{notice}"
        );
    }
}
