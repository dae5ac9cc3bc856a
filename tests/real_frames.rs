//! Frames, poses and labels of the real SemanticKITTI sample: the world frame is
//! right when consecutive scans coincide and the road lies in the world x-y plane.

use std::collections::HashMap;

use travmap_core::config::RemissionScaling;
use travmap_core::geometry::Moments;
use travmap_method::integration::{DriveScan, scan_to_drive};

const VOXEL_M: f32 = 0.5;

fn voxel(p: [f32; 3]) -> [i32; 3] {
    p.map(|v| (v / VOXEL_M).floor() as i32)
}

/// Mean distance (capped at 1 m) from every 20th point of `moving` within 30 m of its
/// sensor to the nearest point of `fixed`.
fn mean_nearest_distance(fixed: &[[f32; 3]], moving: &[[f32; 3]], sensor: [f32; 3]) -> f64 {
    let mut voxels: HashMap<[i32; 3], Vec<[f32; 3]>> = HashMap::new();
    for &p in fixed {
        voxels.entry(voxel(p)).or_default().push(p);
    }
    let (mut sum, mut n) = (0.0f64, 0usize);
    for &p in moving.iter().step_by(20) {
        let r2: f32 = (0..3).map(|k| (p[k] - sensor[k]).powi(2)).sum();
        if r2 > 30.0 * 30.0 {
            continue;
        }
        let v = voxel(p);
        let mut best = 1.0f32;
        for dx in -2..=2 {
            for dy in -2..=2 {
                for dz in -2..=2 {
                    for q in voxels
                        .get(&[v[0] + dx, v[1] + dy, v[2] + dz])
                        .into_iter()
                        .flatten()
                    {
                        let d =
                            ((p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2) + (p[2] - q[2]).powi(2))
                                .sqrt();
                        best = best.min(d);
                    }
                }
            }
        }
        sum += best as f64;
        n += 1;
    }
    sum / n as f64
}

/// The scans in the sequence's world, which is its first scan's frame (its drive frame).
fn world_scans(
    sequence: &[travmap_core::frame::Frame],
    frames: std::ops::Range<usize>,
) -> Vec<DriveScan> {
    frames
        .map(|i| {
            let frame = sequence[i].clone();
            let pose = frame.world_from_velodyne;
            scan_to_drive(frame, &pose, RemissionScaling::AsRead)
        })
        .collect()
}

#[test]
fn consecutive_scans_coincide_in_the_world_frame() {
    let Some(dir) = crate::common::sample() else {
        return;
    };
    let sequence = crate::common::read_frames(&dir);
    let scans = world_scans(&sequence, 0..6);
    for pair in scans.windows(2) {
        let sensor = pair[1].sensor_in_drive.map(|v| v as f32);
        let aligned =
            mean_nearest_distance(&pair[0].points_in_drive, &pair[1].points_in_drive, sensor);
        // The same scan left in its own velodyne frame: the car's motion shows.
        let raw = sequence[pair[1].index].clone();
        let unmoved: Vec<[f32; 3]> = raw
            .points_in_velodyne
            .iter()
            .map(|p| [p[0], p[1], p[2]])
            .collect();
        let first = &sequence[pair[0].index].points_in_velodyne;
        let first: Vec<[f32; 3]> = first.iter().map(|p| [p[0], p[1], p[2]]).collect();
        let unaligned = mean_nearest_distance(&first, &unmoved, [0.0; 3]);
        // The cam0 pose applied to velodyne points as it is, without Tr: a frame mix-up.
        let cam0_pose =
            crate::common::read_trajectory(&dir.join("poses.txt"))[pair[1].index].to_homogeneous();
        let mixed_up: Vec<[f32; 3]> = unmoved
            .iter()
            .map(|p| {
                let v =
                    cam0_pose * nalgebra::Vector4::new(p[0] as f64, p[1] as f64, p[2] as f64, 1.0);
                [v[0] as f32, v[1] as f32, v[2] as f32]
            })
            .collect();
        let mixed_up = mean_nearest_distance(&first, &mixed_up, [0.0; 3]);
        eprintln!(
            "frames {}-{}: mean NN distance {aligned:.3} m with poses, {unaligned:.3} m without, {mixed_up:.3} m with the cam0 pose unconjugated",
            pair[0].index, pair[1].index
        );
        assert!(
            aligned < 0.12,
            "scans {} and {} do not line up: {aligned} m",
            pair[0].index,
            pair[1].index
        );
        assert!(
            unaligned > 1.5 * aligned,
            "the check cannot tell poses apart: {aligned} vs {unaligned}"
        );
        assert!(
            mixed_up > 1.5 * aligned,
            "a frame mix-up goes unnoticed: {aligned} vs {mixed_up}"
        );
    }
    // The car drives forward (velodyne +x) about 0.7 m per frame, on the ground plane.
    let last = scans[5].sensor_in_drive;
    assert!(
        last[0] > 3.0 && last[0] < 4.5 && last[1].abs() < 0.3 && last[2].abs() < 0.1,
        "{last:?}"
    );
}

#[test]
fn the_road_lies_in_the_world_xy_plane() {
    let Some(dir) = crate::common::sample() else {
        return;
    };
    let sequence = crate::common::read_frames(&dir);
    for scan in world_scans(&sequence, 0..3) {
        let labels = scan.labels.as_ref().expect("frames 0-2 are labelled");
        let mut road = Moments::default();
        for (p, &label) in scan.points_in_drive.iter().zip(labels) {
            let horizontal = ((p[0] as f64 - scan.sensor_in_drive[0]).powi(2)
                + (p[1] as f64 - scan.sensor_in_drive[1]).powi(2))
            .sqrt();
            if label & 0xFFFF == 40 && horizontal < 15.0 {
                road.add(p.map(|v| v as f64));
            }
        }
        let normal = road.covariance().smallest_eigen().normal;
        let height = road.mean()[2];
        eprintln!(
            "frame {}: {} road points, normal {normal:.4?}, mean z {height:.3} m",
            scan.index, road.count
        );
        assert!(road.count > 5000);
        assert!(normal[2] > 0.995, "road normal {normal:?} is not +z");
        // The HDL-64E sits 1.73 m above the road on the KITTI car.
        assert!((height + 1.73).abs() < 0.15, "road at z = {height}");
    }
}

#[test]
fn shipped_scans_and_labels_match_their_provenance() {
    let Some(dir) = crate::common::sample() else {
        return;
    };
    let sequence = crate::common::read_frames(&dir);
    let numbers: Vec<usize> = sequence.iter().map(|f| f.index).collect();
    assert_eq!(numbers, [0, 1, 2, 3, 4, 5]);
    let counts: Vec<usize> = (0..6)
        .map(|i| sequence[i].clone().points_in_velodyne.len())
        .collect();
    assert_eq!(counts, [124668, 124605, 124478, 124167, 123969, 123924]);
    let labelled: Vec<bool> = sequence.iter().map(|f| f.labels.is_some()).collect();
    assert_eq!(labelled, [true, true, true, false, false, false]);
    let stamps: Vec<u64> = sequence[..3].iter().map(|f| f.stamp_ns).collect();
    assert_eq!(stamps, [0, 103_735_900, 207_338_100]);
}

#[test]
fn labels_join_the_right_points() {
    // The mmdetection3d 50-point subset of frame 0 with its labels, at the indices
    // PROVENANCE.md lists: each point and label must equal the full frame's.
    let (Some(full), Some(subset)) = (
        crate::common::sample(),
        crate::common::shared_data("semantickitti-mmdet3d-50pt/sequences/00"),
    ) else {
        return;
    };
    let indices = [
        5257, 3451, 5359, 2872, 6064, 383, 1077, 7600, 2837, 1835, 5325, 6848, 6742, 1189, 6368,
        437, 4318, 1489, 2300, 5897, 4235, 9606, 2209, 4381, 1432, 1295, 274, 6737, 3424, 160,
        8766, 65, 3829, 6474, 6590, 4106, 5927, 2873, 1495, 2210, 946, 9473, 4990, 7150, 7285,
        1042, 7475, 6645, 6029, 5251,
    ];
    let frame = crate::common::read_frames(&full).remove(0);
    let labels = frame.labels.unwrap();
    let scan_path = subset.join("velodyne/000000.bin");
    let points = crate::common::kitti_scan(&scan_path);
    let subset_labels = crate::common::kitti_labels(&subset.join("labels/000000.label"));
    assert_eq!(subset_labels.len(), points.len());
    for ((p, l), &i) in points.iter().zip(&subset_labels).zip(&indices) {
        assert_eq!(*p, frame.points_in_velodyne[i]);
        assert_eq!(*l, labels[i]);
    }
}

#[test]
fn frames_in_batches_equal_frames_one_by_one() {
    use travmap_core::frame::Frame;
    use travmap_core::posing::{DriveFrame, Posing};
    use travmap_method::classifier::SvmModel;
    use travmap_method::pipeline::Pipeline;
    let Some(dir) = crate::common::sample() else {
        return;
    };
    let sequence = crate::common::read_frames(&dir);
    let model = SvmModel::embedded(travmap_core::config::LabelRule::Road).unwrap();
    let config = travmap_core::Config::default();
    let frames: Vec<_> = (0..6).map(|i| sequence[i].clone()).collect();
    let pipeline = || Pipeline::new(&config, Posing::Recorded, DriveFrame::default()).unwrap();
    let posed = |pipeline: &mut Pipeline, frames: &[Frame]| -> Vec<_> {
        let pose = |f: &Frame| pipeline.pose(f.clone()).unwrap();
        frames.iter().map(pose).collect()
    };
    let mut sequential = pipeline();
    let one_by_one: Vec<_> = frames
        .iter()
        .map(|f| sequential.process_frame(f.clone(), Some(&model)).unwrap())
        .collect();
    let mut whole = pipeline();
    let all = posed(&mut whole, &frames);
    let whole = whole.process_frames(all, Some(&model));
    // Two batches, the second starting with a window the first filled.
    let mut batched = pipeline();
    let (first, second) = (
        posed(&mut batched, &frames[..2]),
        posed(&mut batched, &frames[2..]),
    );
    let mut halves = batched.process_frames(first, Some(&model));
    halves.extend(batched.process_frames(second, Some(&model)));
    // Warm-up frames fill the window without results.
    let mut warmed = pipeline();
    for frame in posed(&mut warmed, &frames[..3]) {
        warmed.warm_up(frame);
    }
    let rest = posed(&mut warmed, &frames[3..]);
    let after_warm_up = warmed.process_frames(rest, Some(&model));
    assert_eq!(whole.len(), 6);
    assert_eq!(halves.len(), 6);
    let pairs = one_by_one
        .iter()
        .zip(&whole)
        .chain(one_by_one.iter().zip(&halves))
        .chain(one_by_one[3..].iter().zip(&after_warm_up));
    for (a, b) in pairs {
        assert_eq!(a.index, b.index);
        assert_eq!(a.layout, b.layout);
        assert_eq!(a.features, b.features);
        assert_eq!(a.filtered, b.filtered);
        assert_eq!(a.ground_truth, b.ground_truth);
    }
}
