//! Appearance features: the camera model on a real KITTI frame, and a scene where
//! only colour separates the classes.

use std::path::{Path, PathBuf};

use crate::common::{arg, json_summary, success, travmap};
use travmap_core::frame::CameraImage;
use travmap_io::kitti::{read_calibration, read_scan};
use travmap_io::payloads::image::decode_png;

/// The matrix of `key` (3x4, or 3x3 for R0_rect) in a KITTI calib file, parsed by
/// hand (independent of travmap).
fn calib_matrix(path: &Path, key: &str) -> Vec<f64> {
    let text = std::fs::read_to_string(path).unwrap();
    let line = text
        .lines()
        .find(|l| l.starts_with(&format!("{key}:")))
        .unwrap();
    line.split_whitespace()
        .skip(1)
        .map(|v| v.parse().unwrap())
        .collect()
}

#[test]
fn every_point_of_the_camera_cropped_kitti_scan_lands_in_its_image() {
    let Some(dir) = crate::common::shared_data("kitti-object-000008/training") else {
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

/// A flat road whose left half (y > 0) is green vegetation and right half grey road,
/// seen by the real KITTI sequence-03 cameras while driving straight ahead: the
/// geometry of both halves is the same plane, only the colour differs.
fn write_colour_scene(dir: &Path, meta: &Path, frames: usize) {
    const HEIGHT_M: f64 = 1.73;
    std::fs::create_dir_all(dir.join("velodyne")).unwrap();
    std::fs::create_dir_all(dir.join("labels")).unwrap();
    std::fs::create_dir_all(dir.join("image_2")).unwrap();
    std::fs::copy(meta.join("calib.txt"), dir.join("calib.txt")).unwrap();
    // cam0 poses: 0.4 m forward (cam0 z is velodyne x) per frame.
    let poses: String = (0..frames)
        .map(|i| format!("1 0 0 0 0 1 0 0 0 0 1 {}\n", 0.4 * i as f64))
        .collect();
    std::fs::write(dir.join("poses.txt"), poses).unwrap();
    let times: String = (0..frames)
        .map(|i| format!("{}\n", 0.1 * i as f64))
        .collect();
    std::fs::write(dir.join("times.txt"), times).unwrap();

    // The image: every pixel's ray hits the plane z = -1.73 in the velodyne frame
    // left (green) or right (grey) of y = 0; above the horizon, sky.
    let calibration = read_calibration(&dir.join("calib.txt")).unwrap();
    let p2 = calibration.projections[2].unwrap();
    let velodyne_from_cam0 = calibration.cam0_from_velodyne.try_inverse().unwrap();
    let (fx, fy, cx, cy) = (p2[(0, 0)], p2[(1, 1)], p2[(0, 2)], p2[(1, 2)]);
    let t = [p2[(0, 3)] / fx, p2[(1, 3)] / fy, p2[(2, 3)]];
    let origin = velodyne_from_cam0 * nalgebra::Vector4::new(-t[0], -t[1], -t[2], 1.0);
    let (width, height) = (1242u32, 375u32);
    let mut rgb = Vec::with_capacity((width * height * 3) as usize);
    for v in 0..height {
        for u in 0..width {
            let d = velodyne_from_cam0
                * nalgebra::Vector4::new(
                    (u as f64 + 0.5 - cx) / fx,
                    (v as f64 + 0.5 - cy) / fy,
                    1.0,
                    0.0,
                );
            let colour = if d.z < -1e-6 {
                let s = (-HEIGHT_M - origin.z) / d.z;
                if origin.y + s * d.y > 0.0 {
                    [40, 150, 40]
                } else {
                    [120, 120, 120]
                }
            } else {
                [200, 210, 255]
            };
            rgb.extend_from_slice(&colour);
        }
    }
    let mut png_bytes = Vec::new();
    {
        let mut encoder = png::Encoder::new(&mut png_bytes, width, height);
        encoder.set_color(png::ColorType::Rgb);
        encoder.set_depth(png::BitDepth::Eight);
        encoder
            .write_header()
            .unwrap()
            .write_image_data(&rgb)
            .unwrap();
    }

    // The plane in the world where the camera sees it (7.5 to 12 m ahead), from each
    // frame's velodyne frame; 0.1 m spacing.
    for i in 0..frames {
        let forward = 0.4 * i as f64;
        let mut scan = Vec::new();
        let mut labels = Vec::new();
        for a in 0..45 {
            for b in 0..130 {
                let (x, y) = (7.5 + 0.1 * a as f64 + 0.013, -6.5 + 0.1 * b as f64 + 0.017);
                for v in [(x - forward) as f32, y as f32, -HEIGHT_M as f32, 0.3] {
                    scan.extend_from_slice(&v.to_le_bytes());
                }
                labels.extend_from_slice(&(if y > 0.0 { 70u32 } else { 40 }).to_le_bytes());
            }
        }
        std::fs::write(dir.join(format!("velodyne/{i:06}.bin")), scan).unwrap();
        std::fs::write(dir.join(format!("labels/{i:06}.label")), labels).unwrap();
        std::fs::write(dir.join(format!("image_2/{i:06}.png")), &png_bytes).unwrap();
    }
}

/// The search grid of the quick training runs (`--set` settings), on a grid that
/// sees the images: KITTI's camera sees the road from ~6 m ahead, and a 24 m grid
/// (12 m ahead) overlaps it.
const QUICK: [&str; 4] = [
    "training.c_values=[1.0, 10.0]",
    "training.gamma_values=[0.05, 0.2]",
    "training.grid_size_m=24",
    "grid.size_m=24",
];

/// `args` followed by the quick search grid.
fn quick<'a>(args: &[&'a str]) -> Vec<&'a str> {
    crate::common::with_settings(args, &QUICK)
}

/// The colour scene of `frames` frames in `<temporary directory>/seq`: the directory
/// and the sequence; None without the shared data.
fn colour_scene(frames: usize) -> Option<(tempfile::TempDir, PathBuf)> {
    let meta = crate::common::shared_data("kitti-odometry-meta/sequences/03")?;
    let dir = tempfile::tempdir().unwrap();
    let seq = dir.path().join("seq");
    write_colour_scene(&seq, &meta, frames);
    Some((dir, seq))
}

#[test]
fn colour_separates_what_geometry_cannot() {
    let Some((dir, seq)) = colour_scene(4) else {
        return;
    };
    let seq = arg(&seq);
    let model = dir.path().join("m.json");
    let model = arg(&model);
    let trained = json_summary(&quick(&["train", seq, "-o", model]));
    assert!(
        trained["hybrid"].is_object(),
        "a hybrid model is trained when images exist: {trained}"
    );
    let eval = |input: &str| json_summary(&quick(&["eval", input, "--model", model]));
    let doc = eval(seq);
    let hybrid = doc["unfiltered_scores"]["accuracy"].as_f64().unwrap();
    let geometric = doc["geometry_only"]["unfiltered_scores"]["accuracy"]
        .as_f64()
        .unwrap();
    eprintln!("colour scene, SVM accuracy: hybrid {hybrid:.3}, geometry only {geometric:.3}");
    assert!(doc["cells_with_appearance"].as_u64().unwrap() > 500);
    assert!(hybrid > 0.95, "hybrid {hybrid}");
    assert!(
        geometric < 0.8,
        "geometry only {geometric}: the halves are the same plane"
    );
    // The same scene as MCAP (PNG images, CameraInfo, /tf_static) gives the same result.
    let drive = dir.path().join("scene.mcap");
    crate::common::write_output("convert", seq, &drive, &[]);
    let from_mcap = eval(arg(&drive));
    assert_eq!(
        from_mcap["cells_with_appearance"],
        doc["cells_with_appearance"]
    );
    assert_eq!(from_mcap["confusion"], doc["confusion"]);
    assert_eq!(
        from_mcap["geometry_only"]["confusion"],
        doc["geometry_only"]["confusion"]
    );
    // annotate reads the images for the hybrid model and predicts as eval does; for
    // the embedded geometry-only model, which they cannot change, it reads none.
    let out = dir.path().join("a.mcap");
    let annotated = |model: &[&str]| {
        let args = [
            &["annotate", seq, "-o", arg(&out), "--no-passthrough"],
            model,
        ]
        .concat();
        json_summary(&quick(&args))
    };
    let with_hybrid = annotated(&["--model", model]);
    assert_eq!(with_hybrid["confusion"], doc["confusion"]);
    assert_eq!(
        with_hybrid["cells_with_appearance"],
        doc["cells_with_appearance"]
    );
    assert_eq!(annotated(&[])["frames_with_images"], 0);
    // The text output shows both rows.
    let text = success(travmap(&quick(&["eval", seq, "--model", model])));
    assert!(
        text.contains("ablation") && text.matches("travmap (filtered)").count() == 2,
        "{text}"
    );
}

#[test]
fn a_cell_keeps_its_colour_five_frames_later_after_the_grid_moved() {
    use travmap_method::pipeline::Pipeline;
    let Some((_dir, seq)) = colour_scene(6) else {
        return;
    };
    // Only frame 0 has an image.
    for i in 1..6 {
        std::fs::remove_file(seq.join(format!("image_2/{i:06}.png"))).unwrap();
    }
    let mut config = travmap_core::Config::default();
    config.grid.size_m = 24.0;
    let sequence = travmap_io::KittiSequence::open(&seq, None, &|_| {}).unwrap();
    let mut pipeline = Pipeline::new(
        &config,
        travmap_core::posing::Posing::Recorded,
        travmap_core::posing::DriveFrame::default(),
    )
    .unwrap();
    let results: Vec<_> = (0..6)
        .map(|i| {
            let frame = sequence.read_frame(i).unwrap();
            pipeline.process_frame(frame, None).unwrap()
        })
        .collect();
    let (first, last) = (&results[0], &results[5]);
    assert_ne!(first.layout, last.layout, "the grid moved (2 m, 5 cells)");
    let seen: Vec<usize> = (0..first.layout.cell_count())
        .filter(|&c| first.features.appearance(c).is_some())
        .collect();
    assert!(seen.len() > 100, "{} cells seen in frame 0", seen.len());
    let mut kept = 0;
    for &cell in &seen {
        let key = first.layout.cell_key(cell);
        if let Some(later) = (0..last.layout.cell_count()).find(|&c| last.layout.cell_key(c) == key)
        {
            assert_eq!(
                last.features.appearance(later),
                first.features.appearance(cell),
                "cell {key:?}"
            );
            kept += 1;
        }
    }
    assert!(
        kept > 100,
        "{kept} seen cells still in the grid five frames later"
    );
}
