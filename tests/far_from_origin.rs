//! A drive far from the world's origin maps exactly as the same drive at it (issue:
//! poses in UTM, a national grid or an MGRS square gave a wrong map, exit 0). The
//! shipped sample is moved by a pure translation (its poses rewritten with every
//! digit kept) and each command's cells must be the unmoved drive's, with the world
//! positions they carry moved by the same translation.

use std::path::{Path, PathBuf};

use crate::common::{arg, json_records, messages, sample, success, travmap, write_output};
use travmap_core::Config;
use travmap_formats::ros::{OccupancyGrid, PointCloud2};
use travmap_method::training_set::TrainingSet;
use travmap_outputs::annotation::{CLOUD_TOPIC, DRIVE_MAP_TOPIC, PREDICTION_TOPIC};
use travmap_outputs::dataset::reading::{Labels, read_training_rows};

/// The sample with `offset_m` added to every pose's x and z (KITTI's camera frame:
/// both horizontal), its scans, labels, calibration and times linked.
fn moved_sample(sample: &Path, dir: &Path, offset_m: f64) -> PathBuf {
    let moved = dir.join(format!("moved-{offset_m}"));
    std::fs::create_dir_all(&moved).unwrap();
    for name in ["velodyne", "labels", "calib.txt", "times.txt"] {
        std::os::unix::fs::symlink(sample.join(name), moved.join(name)).unwrap();
    }
    let poses: String = std::fs::read_to_string(sample.join("poses.txt"))
        .unwrap()
        .lines()
        .map(|line| {
            let mut values: Vec<f64> = line
                .split_whitespace()
                .map(|v| v.parse().unwrap())
                .collect();
            values[3] += offset_m;
            values[11] += offset_m;
            // `{:?}` prints the shortest form that reads back to the same f64.
            let words: Vec<String> = values.iter().map(|v| format!("{v:?}")).collect();
            words.join(" ") + "\n"
        })
        .collect();
    std::fs::write(moved.join("poses.txt"), poses).unwrap();
    moved
}

/// `run --json`'s frame records: (frame, cells, world corner).
fn run_frames(input: &Path) -> Vec<(u64, Vec<i64>, [f64; 2])> {
    let (frames, _) = json_records(&success(travmap(&["run", arg(input), "--json", "-q"])));
    frames
        .iter()
        .map(|f| {
            let cells = f["cells"]
                .as_array()
                .unwrap()
                .iter()
                .map(|c| c.as_i64().unwrap());
            let corner = &f["min_corner_in_world"];
            let corner = [0, 1].map(|i| corner[i].as_f64().unwrap());
            (f["frame"].as_u64().unwrap(), cells.collect(), corner)
        })
        .collect()
}

/// Fails unless `to` is `from` moved by `shift` (x, y), within `tolerance_m`.
fn assert_moved(from: [f64; 2], to: [f64; 2], shift: [f64; 2], tolerance_m: f64) {
    let error = (to[0] - from[0] - shift[0]).hypot(to[1] - from[1] - shift[1]);
    assert!(
        error < tolerance_m,
        "{from:?} -> {to:?} is not a move by {shift:?}"
    );
}

/// The world translation between two runs of the same drive, from their first
/// frames' grid corners (checked to be the same for every frame).
fn shift_between(
    at_origin: &[(u64, Vec<i64>, [f64; 2])],
    moved: &[(u64, Vec<i64>, [f64; 2])],
) -> [f64; 2] {
    assert_eq!(at_origin.len(), moved.len());
    let shift = [0, 1].map(|i| moved[0].2[i] - at_origin[0].2[i]);
    for (a, b) in at_origin.iter().zip(moved) {
        assert_eq!(a.0, b.0);
        assert!(a.1 == b.1, "frame {}: the moved drive's cells differ", a.0);
        assert_moved(a.2, b.2, shift, 1e-6);
    }
    shift
}

/// Every message of `topic` in an MCAP, decoded.
fn decoded<T: serde::de::DeserializeOwned>(mcap: &Path, topic: &str) -> Vec<T> {
    messages(mcap, topic).into_iter().map(|(_, m)| m).collect()
}

/// A cloud's (x, y, z) float64 points.
fn cloud_points(cloud: &PointCloud2) -> Vec<[f64; 3]> {
    cloud
        .data
        .chunks_exact(cloud.point_step as usize)
        .map(|p| [0, 8, 16].map(|at| f64::from_le_bytes(p[at..at + 8].try_into().unwrap())))
        .collect()
}

fn assert_grids_moved(at_origin: &[OccupancyGrid], moved: &[OccupancyGrid], shift: [f64; 2]) {
    assert_eq!(at_origin.len(), moved.len());
    for (a, b) in at_origin.iter().zip(moved) {
        assert!(a.data == b.data, "a grid's cells differ");
        assert_eq!((a.info.width, a.info.height), (b.info.width, b.info.height));
        let moved_by = [
            b.info.origin.position.x - a.info.origin.position.x,
            b.info.origin.position.y - a.info.origin.position.y,
        ];
        assert_moved([0.0; 2], moved_by, shift, 1e-6);
    }
}

/// `map`'s nav2 map of `input` in `dir`: its image's bytes and the yaml's origin.
fn nav2_map(input: &Path, dir: &Path) -> (Vec<u8>, [f64; 2]) {
    std::fs::create_dir_all(dir).unwrap();
    let yaml = dir.join("map.yaml");
    write_output("map", input, &dir.join("map.png"), &["--nav2", arg(&yaml)]);
    let text = std::fs::read_to_string(&yaml).unwrap();
    let origin = text
        .lines()
        .find_map(|l| l.strip_prefix("origin: ["))
        .unwrap();
    let origin: Vec<f64> = origin
        .trim_end_matches(']')
        .split(',')
        .map(|v| v.trim().parse().unwrap())
        .collect();
    (
        std::fs::read(dir.join("map.pgm")).unwrap(),
        [origin[0], origin[1]],
    )
}

/// `dataset`'s labelled cells of `input`, written in `dir`.
fn dataset(input: &Path, dir: &Path) -> TrainingSet {
    std::fs::create_dir_all(dir).unwrap();
    let cells = dir.join("cells.parquet");
    write_output("dataset", input, &cells, &[]);
    let config = Config::default();
    let mut set = TrainingSet::default();
    read_training_rows(&cells, &config, &mut set, Labels::GroundTruth).unwrap();
    set
}

#[test]
fn a_drive_moved_by_5000_km_or_300_km_maps_to_the_same_cells_at_its_true_coordinates() {
    let Some(sample) = sample() else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let at_origin = run_frames(&sample);
    let annotated = dir.path().join("at-origin.mcap");
    write_output("annotate", &sample, &annotated, &["--no-passthrough"]);
    let (nav2_image, nav2_origin) = nav2_map(&sample, &dir.path().join("map"));
    let cells = dataset(&sample, &dir.path().join("dataset"));
    for offset_m in [5e6, 3e5] {
        let moved = moved_sample(&sample, dir.path(), offset_m);
        // run: every frame's cells, each grid where the translation puts it.
        let shift = shift_between(&at_origin, &run_frames(&moved));
        assert!(
            shift[0].abs().max(shift[1].abs()) > 0.5 * offset_m,
            "{shift:?}"
        );

        // annotate: the grids, the drive map and the cloud's points (float64), moved.
        let moved_mcap = dir.path().join(format!("moved-{offset_m}.mcap"));
        write_output("annotate", &moved, &moved_mcap, &["--no-passthrough"]);
        for topic in [PREDICTION_TOPIC, DRIVE_MAP_TOPIC] {
            assert_grids_moved(
                &decoded(&annotated, topic),
                &decoded(&moved_mcap, topic),
                shift,
            );
        }
        let clouds = |mcap: &Path| decoded::<PointCloud2>(mcap, CLOUD_TOPIC);
        for (a, b) in clouds(&annotated).iter().zip(clouds(&moved_mcap)) {
            assert_eq!(a.width, b.width);
            let classes =
                |c: &PointCloud2| c.data.chunks_exact(32).map(|p| p[24]).collect::<Vec<_>>();
            assert!(classes(a) == classes(&b), "the points' classes differ");
            for (p, q) in cloud_points(a).iter().zip(cloud_points(&b)) {
                // The points' own f32 precision near the drive frame's origin.
                assert_moved([p[0], p[1]], [q[0], q[1]], shift, 1e-4);
            }
        }

        // map: the nav2 map's pixels, its origin moved.
        let (image, origin) = nav2_map(&moved, &dir.path().join(format!("map-{offset_m}")));
        assert!(image == nav2_image, "the nav2 map's pixels differ");
        assert_moved(nav2_origin, origin, shift, 1e-6);

        // dataset: the same cells and features, at their true coordinates.
        let moved_cells = dataset(&moved, &dir.path().join(format!("dataset-{offset_m}")));
        // The poses' digits read back a nanometre apart (5e6 + x is not x), which
        // the f32 points carry into the last bit of a feature now and then.
        assert_eq!(moved_cells.features.len(), cells.features.len());
        for (i, (a, b)) in cells.features.iter().zip(&moved_cells.features).enumerate() {
            assert!(
                (a - b).abs() <= 1e-4 * a.abs().max(1.0),
                "value {i}: {a} -> {b}"
            );
        }
        assert_eq!(moved_cells.traversable, cells.traversable);
        for (a, b) in cells
            .centre_in_world
            .iter()
            .zip(&moved_cells.centre_in_world)
        {
            assert_moved(*a, *b, shift, 1e-6);
        }

        // The same drive as an MCAP posed by /tf: the same cells again.
        let converted = dir.path().join(format!("moved-{offset_m}-drive.mcap"));
        write_output("convert", &moved, &converted, &[]);
        shift_between(&at_origin, &run_frames(&converted));
    }
}
