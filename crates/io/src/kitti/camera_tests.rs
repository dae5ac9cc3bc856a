//! The KITTI calibration and camera model on a real frame of KITTI's object set
//! (`../shared/data/kitti-object-000008`): every point of the camera-cropped scan
//! lands in the image, where a projection computed here by hand puts it.

use std::path::Path;

use travmap_core::frame::CameraImage;

use super::{read_calibration, read_scan};
use crate::payloads::image::decode_png;
use crate::test_data::shared_data;

/// The numbers after `key:` in a KITTI calib file, read by hand (independent of the
/// reader under test).
fn calib_matrix(path: &Path, key: &str) -> Vec<f64> {
    let text = std::fs::read_to_string(path).unwrap();
    let prefix = format!("{key}:");
    let values = text
        .lines()
        .find_map(|line| line.strip_prefix(prefix.as_str()));
    let values = values.unwrap_or_else(|| panic!("no {key} in {}", path.display()));
    values
        .split_whitespace()
        .map(|v| v.parse().unwrap())
        .collect()
}

#[test]
fn every_point_of_the_camera_cropped_kitti_scan_lands_in_its_image() {
    let Some(dir) = shared_data("kitti-object-000008/training") else {
        return;
    };
    let calib_path = dir.join("calib/000008.txt");
    let calibration = read_calibration(&calib_path).unwrap();
    let image_path = dir.join("image_2/000008.png");
    let image = decode_png(&std::fs::read(&image_path).unwrap(), &image_path).unwrap();
    assert_eq!((image.width, image.height), (1242, 375));
    let camera = CameraImage::new(
        &calibration.projections[2].unwrap(),
        &calibration.cam0_from_velodyne,
        image,
    );
    let points = read_scan(&dir.join("velodyne_reduced/000008.bin")).unwrap();
    assert_eq!(points.len(), 17_238);
    let mut inside = 0;
    for p in &points {
        let px = camera
            .project([p[0] as f64, p[1] as f64, p[2] as f64])
            .expect("in front of the camera");
        if px[0] >= 0.0 && px[1] >= 0.0 && px[0] < 1242.0 && px[1] < 375.0 {
            inside += 1;
        }
    }
    assert_eq!(inside, points.len());

    // Pixels of a few points against P2 * R0_rect * Tr_velo_to_cam computed here by hand.
    let p2 = calib_matrix(&calib_path, "P2");
    let r0 = calib_matrix(&calib_path, "R0_rect");
    let tr = calib_matrix(&calib_path, "Tr_velo_to_cam");
    for &i in &[0usize, 5000, 17_237] {
        let v = [
            points[i][0] as f64,
            points[i][1] as f64,
            points[i][2] as f64,
            1.0,
        ];
        let cam: Vec<f64> = (0..3)
            .map(|r| (0..4).map(|c| tr[4 * r + c] * v[c]).sum())
            .collect();
        let rect: Vec<f64> = (0..3)
            .map(|r| (0..3).map(|c| r0[3 * r + c] * cam[c]).sum())
            .collect();
        let h: Vec<f64> = (0..3)
            .map(|r| (0..3).map(|c| p2[4 * r + c] * rect[c]).sum::<f64>() + p2[4 * r + 3])
            .collect();
        let expected = [h[0] / h[2], h[1] / h[2]];
        let got = camera.project([v[0], v[1], v[2]]).unwrap();
        assert!(
            (got[0] - expected[0]).abs() < 1e-9 && (got[1] - expected[1]).abs() < 1e-9,
            "point {i}: {got:?} vs {expected:?}"
        );
    }
    // Behind the camera: no pixel.
    assert!(camera.project([-10.0, 0.0, 0.0]).is_none());
}
