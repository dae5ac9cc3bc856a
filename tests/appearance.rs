//! Appearance features: the camera model on a real KITTI frame, and a scene where
//! only colour separates the classes.

use std::path::{Path, PathBuf};

use crate::common::{arg, json_summary, success, travmap};

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
    let calib = dir.join("calib.txt");
    let p2 = nalgebra::Matrix3x4::from_row_slice(&calib_matrix(&calib, "P2"));
    let mut cam0_from_velodyne = nalgebra::Matrix4::identity();
    (cam0_from_velodyne.fixed_view_mut::<3, 4>(0, 0)).copy_from(
        &nalgebra::Matrix3x4::from_row_slice(&calib_matrix(&calib, "Tr")),
    );
    let velodyne_from_cam0 = cam0_from_velodyne.try_inverse().unwrap();
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
    let sequence = crate::common::read_frames(&seq);
    let mut pipeline = Pipeline::new(
        &config,
        travmap_core::posing::Posing::Recorded,
        travmap_core::posing::DriveFrame::default(),
    )
    .unwrap();
    let results: Vec<_> = (0..6)
        .map(|i| {
            let frame = sequence[i].clone();
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
