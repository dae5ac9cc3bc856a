//! How a camera's lens bends rays away from the pinhole: the distortion models of ROS's
//! `sensor_msgs/CameraInfo` (`distortion_model` and `D`), with OpenCV's formulas, which
//! the camera drivers' calibrations are made with. A raw image (`image_raw`) is seen
//! through its lens; a rectified one (`image_rect`) is a pinhole already.

/// A lens's distortion, applied to a ray's coordinates on the normalised image plane
/// (x / z, y / z, before the intrinsics K).
#[derive(Clone, Debug, PartialEq)]
pub enum Distortion {
    /// `plumb_bob` (k1, k2, p1, p2, k3) and `rational_polynomial` (k1, k2, p1, p2, k3,
    /// k4, k5, k6): radial `(1 + k1 r^2 + k2 r^4 + k3 r^6) / (1 + k4 r^2 + k5 r^4 +
    /// k6 r^6)` and tangential p1, p2.
    Polynomial {
        radial: [f64; 6],
        tangential: [f64; 2],
    },
    /// `equidistant` (OpenCV's fisheye model): the angle from the axis, theta, bent to
    /// `theta (1 + k1 theta^2 + k2 theta^4 + k3 theta^6 + k4 theta^8)`.
    Equidistant([f64; 4]),
}

/// What the models of a CameraInfo name, for messages.
pub const KNOWN_MODELS: &str = "plumb_bob, rational_polynomial, equidistant";

impl Distortion {
    /// From a CameraInfo's `distortion_model` and `D`: None when D is empty or all
    /// zero (a pinhole: a rectified camera, or one without a calibration); an error
    /// naming the model and D when travmap does not know the model or D's length.
    pub fn of_camera_info(model: &str, d: &[f64]) -> Result<Option<Self>, String> {
        if d.iter().all(|&v| v == 0.0) {
            return Ok(None);
        }
        let unknown = || {
            Err(format!(
                "distortion model `{model}` with {} coefficients {d:?} (travmap knows {KNOWN_MODELS})",
                d.len()
            ))
        };
        if d.iter().any(|v| !v.is_finite()) {
            return unknown();
        }
        let at = |i: usize| d.get(i).copied().unwrap_or(0.0);
        match (model, d.len()) {
            ("plumb_bob", 4 | 5) | ("rational_polynomial", 8) => Ok(Some(Self::Polynomial {
                radial: [at(0), at(1), at(4), at(5), at(6), at(7)],
                tangential: [at(2), at(3)],
            })),
            ("equidistant" | "fisheye", 4) => {
                Ok(Some(Self::Equidistant([at(0), at(1), at(2), at(3)])))
            }
            _ => unknown(),
        }
    }

    /// Where the lens puts the ray through (x, y) on the normalised plane; None where
    /// the model folds back (its radius no longer grows with the ray's), outside
    /// anything the calibration saw.
    pub fn distort(&self, [x, y]: [f64; 2]) -> Option<[f64; 2]> {
        let r2 = x * x + y * y;
        match self {
            Self::Polynomial { radial, tangential } => {
                let [k1, k2, k3, k4, k5, k6] = *radial;
                let scale = |r2: f64| {
                    (1.0 + r2 * (k1 + r2 * (k2 + r2 * k3)))
                        / (1.0 + r2 * (k4 + r2 * (k5 + r2 * k6)))
                };
                // The radius out, r scale(r^2), must still grow at this ray's r.
                let radius_out = |r: f64| r * scale(r * r);
                let (r, s) = (r2.sqrt(), scale(r2));
                if s <= 0.0 || (r > 0.0 && radius_out(r * 1.000_001) <= radius_out(r)) {
                    return None;
                }
                let [p1, p2] = *tangential;
                Some([
                    x * s + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x),
                    y * s + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y,
                ])
            }
            Self::Equidistant([k1, k2, k3, k4]) => {
                let r = r2.sqrt();
                if r == 0.0 {
                    return Some([x, y]);
                }
                let bent = |theta: f64| {
                    let t2 = theta * theta;
                    theta * (1.0 + t2 * (k1 + t2 * (k2 + t2 * (k3 + t2 * k4))))
                };
                let theta = r.atan();
                if bent(theta) <= 0.0 || bent(theta * 1.000_001) <= bent(theta) {
                    return None;
                }
                let factor = bent(theta) / r;
                Some([x * factor, y * factor])
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn models_are_read_as_ros_names_them() {
        assert_eq!(Distortion::of_camera_info("plumb_bob", &[0.0; 5]), Ok(None));
        assert_eq!(Distortion::of_camera_info("", &[]), Ok(None));
        assert_eq!(
            Distortion::of_camera_info("plumb_bob", &[-0.3, 0.1, 0.001, -0.002, 0.05]),
            Ok(Some(Distortion::Polynomial {
                radial: [-0.3, 0.1, 0.05, 0.0, 0.0, 0.0],
                tangential: [0.001, -0.002],
            }))
        );
        assert!(matches!(
            Distortion::of_camera_info("rational_polynomial", &[0.1; 8]),
            Ok(Some(Distortion::Polynomial { radial: [_, _, _, k4, _, _], .. })) if k4 == 0.1
        ));
        assert!(matches!(
            Distortion::of_camera_info("equidistant", &[0.1, 0.0, 0.0, 0.0]),
            Ok(Some(Distortion::Equidistant(_)))
        ));
        let error = Distortion::of_camera_info("kannala_brandt", &[0.1, 0.2]).unwrap_err();
        assert!(
            error.contains("`kannala_brandt` with 2 coefficients"),
            "{error}"
        );
        assert!(Distortion::of_camera_info("plumb_bob", &[f64::NAN, 0.0, 0.0, 0.0, 0.0]).is_err());
    }

    /// Values from OpenCV's formulas worked by hand (cv::projectPoints' model).
    #[test]
    fn rays_bend_as_opencv_bends_them() {
        let lens = Distortion::Polynomial {
            radial: [-0.3, 0.1, 0.05, 0.0, 0.0, 0.0],
            tangential: [0.001, -0.002],
        };
        // (0.2, -0.1): r^2 0.05, radial 1 - 0.015 + 0.00025 + 0.00000625 = 0.98525625,
        // x: 0.19705125 + 2 * 0.001 * -0.02 - 0.002 * 0.13 = 0.19675125,
        // y: -0.098525625 + 0.001 * 0.07 + 2 * -0.002 * -0.02 = -0.098375625.
        let [x, y] = lens.distort([0.2, -0.1]).unwrap();
        assert!(
            (x - 0.19675125).abs() < 1e-12 && (y + 0.098375625).abs() < 1e-12,
            "{x} {y}"
        );
        assert_eq!(lens.distort([0.0, 0.0]), Some([0.0, 0.0]));
        // Strong barrel distortion folds back past r = 1 / sqrt(3 * 0.3) ~ 1.05
        // (k1 alone): a ray beyond it is outside the lens's picture.
        let barrel = Distortion::Polynomial {
            radial: [-0.3, 0.0, 0.0, 0.0, 0.0, 0.0],
            tangential: [0.0, 0.0],
        };
        assert!(barrel.distort([1.0, 0.0]).is_some());
        assert_eq!(barrel.distort([1.2, 0.0]), None);

        // Equidistant: theta = atan(0.5) = 0.4636476, bent by 1 + 0.1 theta^2.
        let fisheye = Distortion::Equidistant([0.1, 0.0, 0.0, 0.0]);
        let theta = 0.5f64.atan();
        let [x, y] = fisheye.distort([0.3, 0.4]).unwrap();
        let expected = theta * (1.0 + 0.1 * theta * theta) / 0.5;
        assert!((x - 0.3 * expected).abs() < 1e-12 && (y - 0.4 * expected).abs() < 1e-12);
    }
}
