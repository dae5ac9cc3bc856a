//! `travmap map --nav2`: the YAML and image loaded as nav2's map_server loads them
//! (`nav2_map_server/src/map_io.cpp`, `loadMapYaml` and `loadMapFromFile`, read at
//! ros-navigation/navigation2 a3a9704), and every fused cell found on its pixel with
//! its value.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use crate::common::{arg, json_summary, tf};
use nalgebra::{Isometry3, Translation3, UnitQuaternion};
use travmap_formats::mcap::writer::Compression;
use travmap_method::fusion::FusedCell;
use travmap_method::grid::CellClass;
use travmap_outputs::conversion::scan_to_cloud;
use travmap_outputs::writing::McapSink;

/// map_server's OccupancyGrid values.
const FREE: i8 = 0;
const OCCUPIED: i8 = 100;
const UNKNOWN: i8 = -1;

/// What map_server makes of a map YAML and its image.
struct LoadedMap {
    width: usize,
    height: usize,
    resolution: f64,
    origin: [f64; 3],
    /// Row-major from the bottom row up (OccupancyGrid order).
    data: Vec<i8>,
}

/// The flat `key: value` YAML map_server reads (comments and `[a, b, c]` lists).
fn parse_yaml(text: &str) -> HashMap<String, String> {
    text.lines()
        .map(|line| line.split('#').next().unwrap().trim())
        .filter(|line| !line.is_empty())
        .map(|line| {
            let (key, value) = line.split_once(':').expect("key: value");
            let value = value.trim().trim_matches('\'').to_string();
            (key.trim().to_string(), value)
        })
        .collect()
}

/// Width, height and the 8-bit grey (and alpha) of each pixel, top row first.
fn read_image(path: &Path) -> (usize, usize, Vec<(u8, u8)>) {
    let bytes = std::fs::read(path).unwrap();
    if bytes.starts_with(b"P5") {
        // P5, whitespace-separated width, height, maxval, one whitespace byte, pixels.
        let mut fields = Vec::new();
        let mut at = 2;
        while fields.len() < 3 {
            while bytes[at].is_ascii_whitespace() {
                at += 1;
            }
            let start = at;
            while bytes[at].is_ascii_digit() {
                at += 1;
            }
            fields.push(
                std::str::from_utf8(&bytes[start..at])
                    .unwrap()
                    .parse::<usize>()
                    .unwrap(),
            );
        }
        assert_eq!(fields[2], 255, "maxval");
        let pixels = &bytes[at + 1..];
        assert_eq!(pixels.len(), fields[0] * fields[1], "one byte per pixel");
        return (
            fields[0],
            fields[1],
            pixels.iter().map(|&g| (g, 255)).collect(),
        );
    }
    let mut reader = png::Decoder::new(std::io::Cursor::new(bytes))
        .read_info()
        .unwrap();
    let mut buffer = vec![0; reader.output_buffer_size().unwrap()];
    let info = reader.next_frame(&mut buffer).unwrap();
    assert_eq!(info.color_type, png::ColorType::GrayscaleAlpha);
    let pixels = buffer[..info.buffer_size()]
        .chunks(2)
        .map(|ga| (ga[0], ga[1]))
        .collect();
    (info.width as usize, info.height as usize, pixels)
}

/// `loadMapYaml` + `loadMapFromFile`: the image relative to the YAML's folder; each
/// pixel's occupancy `p = 1 - g / 255` in float32 (negate 0); occupied if
/// `p >= occupied_thresh`, free if `p <= free_thresh` (free wins), scale mode spreads
/// the values between over 0..100 with `rint`; a pixel less than opaque is unknown in
/// scale mode; image row 0 becomes the grid's top row.
fn load_like_map_server(yaml: &Path) -> LoadedMap {
    let doc = parse_yaml(&std::fs::read_to_string(yaml).unwrap());
    let number = |key: &str| doc[key].parse::<f64>().unwrap();
    assert_eq!(doc["negate"], "0");
    let mode = doc
        .get("mode")
        .map_or("trinary", String::as_str)
        .to_string();
    let origin: Vec<f64> = doc["origin"]
        .trim_matches(['[', ']'])
        .split(',')
        .map(|v| v.trim().parse().unwrap())
        .collect();
    let image = yaml.parent().unwrap().join(&doc["image"]);
    let (width, height, pixels) = read_image(&image);
    let (free_thresh, occupied_thresh) = (number("free_thresh"), number("occupied_thresh"));
    let (free, occupied) = (free_thresh as f32, occupied_thresh as f32);
    let mut data = vec![0i8; width * height];
    for row in 0..height {
        for col in 0..width {
            let (grey, alpha) = pixels[row * width + col];
            let p = 1.0f32 - grey as f32 / 255.0f32;
            let mut value = UNKNOWN;
            if p >= occupied {
                value = OCCUPIED;
            }
            if p <= free {
                value = FREE;
            }
            if mode == "scale" {
                if free < p && p < occupied {
                    let span = (occupied_thresh - free_thresh) as f32;
                    value = ((p - free) / span * 100.0).round() as i8;
                }
                if alpha < 255 {
                    value = UNKNOWN;
                }
            }
            data[(height - 1 - row) * width + col] = value;
        }
    }
    LoadedMap {
        width,
        height,
        resolution: number("resolution"),
        origin: [origin[0], origin[1], origin[2]],
        data,
    }
}

impl LoadedMap {
    /// The grid cell of a world point (nav2's `worldToMap`).
    fn at(&self, x_m: f64, y_m: f64) -> Option<i8> {
        let mx = ((x_m - self.origin[0]) / self.resolution).floor();
        let my = ((y_m - self.origin[1]) / self.resolution).floor();
        let inside =
            mx >= 0.0 && my >= 0.0 && (mx as usize) < self.width && (my as usize) < self.height;
        inside.then(|| self.data[my as usize * self.width + mx as usize])
    }
}

fn write_nav2(seq: &Path, dir: &Path, mode: &str) -> (PathBuf, serde_json::Value) {
    let yaml = dir.join(format!("site-{mode}.yaml"));
    let png = dir.join(format!("map-{mode}.png"));
    let summary = json_summary(&[
        "map",
        arg(seq),
        "-o",
        arg(&png),
        "--nav2",
        arg(&yaml),
        "--nav2-mode",
        mode,
    ]);
    (yaml, summary)
}

#[test]
fn map_server_loads_every_fused_cell_on_its_pixel_with_its_value() {
    let Some(seq) = crate::common::sample() else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let cells = crate::common::fused_drive(&seq);
    let seen: Vec<&FusedCell> = cells.iter().filter(|c| c.observations > 0).collect();
    assert!(seen.len() > 900, "{} cells seen", seen.len());

    let (yaml, summary) = write_nav2(&seq, dir.path(), "trinary");
    assert_eq!(
        summary["nav2"]["image"],
        arg(&dir.path().join("site-trinary.pgm"))
    );
    assert_eq!(summary["nav2"]["frame"], "map");
    let map = load_like_map_server(&yaml);
    assert_eq!(map.resolution, 0.4);
    assert_eq!(map.origin[2], 0.0);
    let expected = |cell: &FusedCell| match cell.class {
        CellClass::Traversable => FREE,
        CellClass::NonTraversable => OCCUPIED,
        CellClass::Unknown => UNKNOWN,
    };
    let mut on_pixel = 0;
    for cell in &seen {
        assert_eq!(map.at(cell.x_m, cell.y_m), Some(expected(cell)), "{cell:?}");
        on_pixel += 1;
    }
    assert_eq!(on_pixel, seen.len());
    // The lower-left pixel is the lowest seen cell in x and in y; the rest unknown.
    let low = |axis: usize| seen.iter().map(|c| c.key[axis]).min().unwrap() as f64 * 0.4;
    assert!((map.origin[0] - low(0)).abs() < 1e-9 && (map.origin[1] - low(1)).abs() < 1e-9);
    let unknown = map.data.iter().filter(|&&v| v == UNKNOWN).count();
    let seen_unknown = seen
        .iter()
        .filter(|c| c.class == CellClass::Unknown)
        .count();
    assert_eq!(unknown, map.width * map.height - seen.len() + seen_unknown);
    assert!(map.data.contains(&FREE) && map.data.contains(&OCCUPIED));

    // Scale mode: P(not traversable) spread over the thresholds, unseen transparent.
    let (yaml, summary) = write_nav2(&seq, dir.path(), "scale");
    assert_eq!(summary["nav2"]["mode"], "scale");
    let scale = load_like_map_server(&yaml);
    assert_eq!(
        (scale.width, scale.height, scale.origin),
        (map.width, map.height, map.origin)
    );
    for cell in &seen {
        let p_not = 1.0 - (255.0 * cell.probability).round() / 255.0;
        let value = scale.at(cell.x_m, cell.y_m).unwrap();
        let want = if p_not >= 0.65 {
            100.0
        } else if p_not <= 0.196 {
            0.0
        } else {
            (p_not - 0.196) / (0.65 - 0.196) * 100.0
        };
        assert!(
            (value as f64 - want).abs() <= 1.0,
            "{cell:?}: {value} against {want}"
        );
    }
    assert_eq!(
        scale.data.iter().filter(|&&v| v == UNKNOWN).count(),
        scale.width * scale.height - seen.len()
    );
}

#[test]
fn a_nav2_map_beside_an_input_or_twice_named_is_refused() {
    let Some(seq) = crate::common::sample() else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let png = dir.path().join("site.png");
    let yaml = dir.path().join("site.yaml");
    // --nav2-mode scale would write site.png: the picture's own name.
    let err = crate::common::clean_failure(crate::common::travmap(&[
        "map",
        arg(&seq),
        "-o",
        arg(&png),
        "--nav2",
        arg(&yaml),
        "--nav2-mode",
        "scale",
    ]));
    crate::common::assert_contains(&err, &["site.png"]);
    assert!(!yaml.exists() && !png.exists());
}

#[test]
fn a_nav2_map_alone_is_written_and_every_file_is_named() {
    let Some(seq) = crate::common::sample() else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let yaml = dir.path().join("site.yaml");
    let alone = crate::common::success(crate::common::travmap(&[
        "map",
        arg(&seq),
        "--nav2",
        arg(&yaml),
    ]));
    let pgm = dir.path().join("site.pgm");
    crate::common::assert_contains(&alone, &["wrote", "site.yaml", "site.pgm"]);
    assert!(yaml.exists() && pgm.exists());
    assert_eq!(
        std::fs::read_dir(dir.path()).unwrap().count(),
        2,
        "nothing else"
    );
    // The picture and the cells are each named as written.
    let (png, cells) = (dir.path().join("m.png"), dir.path().join("c.parquet"));
    let both = crate::common::success(crate::common::travmap(&[
        "map",
        arg(&seq),
        "-o",
        arg(&png),
        "--cells",
        arg(&cells),
    ]));
    crate::common::assert_contains(
        &both,
        &[
            &format!("wrote {} (the map's picture)", png.display()),
            &format!("wrote {} (", cells.display()),
        ],
    );
    // A map that writes nothing is a usage error.
    let err = crate::common::usage_error(crate::common::travmap(&["map", arg(&seq)]));
    crate::common::assert_contains(&err, &["-o map.png", "--cells", "--nav2"]);
}

#[test]
fn annotate_writes_the_final_map_once_on_a_latched_map_topic() {
    let Some(seq) = crate::common::sample() else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("a.mcap");
    crate::common::write_output(
        "annotate",
        &seq,
        &out,
        &["--static-map", "--no-passthrough"],
    );
    let bytes = std::fs::read(&out).unwrap();
    let maps: Vec<_> = mcap::MessageStream::new(&bytes)
        .unwrap()
        .map(Result::unwrap)
        .filter(|m| m.channel.topic == "/map")
        .collect();
    assert_eq!(maps.len(), 1, "the map is written once, at the end");
    let qos = &maps[0].channel.metadata["offered_qos_profiles"];
    assert!(
        qos.contains("durability: 1") && qos.contains("reliability: 1"),
        "{qos}"
    );
    let grid: travmap_formats::ros::OccupancyGrid =
        travmap_formats::ros::decode(&maps[0].data).unwrap();
    assert_eq!(grid.header.frame_id, "map");
    assert_eq!(grid.info.resolution, 0.4);
    let cells = crate::common::fused_drive(&seq);
    let (ox, oy) = (grid.info.origin.position.x, grid.info.origin.position.y);
    let width = grid.info.width as usize;
    for cell in cells.iter().filter(|c| c.observations > 0) {
        let col = ((cell.x_m - ox) / 0.4).floor() as usize;
        let row = ((cell.y_m - oy) / 0.4).floor() as usize;
        let expected = match cell.class {
            CellClass::Traversable => FREE,
            CellClass::NonTraversable => OCCUPIED,
            CellClass::Unknown => UNKNOWN,
        };
        assert_eq!(grid.data[row * width + col], expected, "{cell:?}");
    }
    let unseen = grid.data.iter().filter(|&&v| v == UNKNOWN).count();
    let seen = cells.iter().filter(|c| c.observations > 0).count();
    assert!(unseen >= grid.data.len() - seen);
}

/// The shipped drive as an MCAP whose poses are `map -> velodyne` on /tf, with `utm`
/// placed on /tf_static as `place` says: `Some(true)` as the root above `map`,
/// `Some(false)` as a child of `map` (robot_localization's navsat_transform
/// default), None not at all.
fn write_placed_log(seq: &Path, path: &Path, utm_from_map: &Isometry3<f64>, place: Option<bool>) {
    let source = travmap_io::Source::open(seq, &Default::default(), &|_| {}).unwrap();
    let mut sink = McapSink::create(path, Compression::Zstd).unwrap();
    let start_ns = 1_600_000_000_000_000_000;
    match place {
        Some(true) => sink.write(
            "/tf_static",
            start_ns,
            &tf(start_ns, "utm", "map", utm_from_map),
        ),
        Some(false) => sink.write(
            "/tf_static",
            start_ns,
            &tf(start_ns, "map", "utm", &utm_from_map.inverse()),
        ),
        None => Ok(()),
    }
    .unwrap();
    for frame in source.read(&(0..usize::MAX)).map(Result::unwrap) {
        let stamp = start_ns + frame.stamp_ns;
        sink.write(
            "/tf",
            stamp,
            &tf(stamp, "map", "velodyne", &frame.world_from_velodyne),
        )
        .unwrap();
        sink.write("/points", stamp, &scan_to_cloud(&frame, stamp))
            .unwrap();
    }
    sink.finish().unwrap();
}

#[test]
fn a_log_placed_in_utm_gets_its_map_placed_there() {
    let Some(seq) = crate::common::sample() else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let yaw = 30f64.to_radians();
    let utm_from_map = Isometry3::from_parts(
        Translation3::new(512_000.5, 4_100_000.25, 30.0),
        UnitQuaternion::from_euler_angles(0.0, 0.0, yaw),
    );
    let mut maps = Vec::new();
    for (name, place) in [("none", None), ("root", Some(true)), ("child", Some(false))] {
        let log = dir.path().join(format!("{name}.mcap"));
        write_placed_log(&seq, &log, &utm_from_map, place);
        let yaml = dir.path().join(format!("{name}.yaml"));
        let png = dir.path().join(format!("{name}.png"));
        let summary = json_summary(&["map", arg(&log), "-o", arg(&png), "--nav2", arg(&yaml)]);
        let nav2 = &summary["nav2"];
        // Mapped in `map` whichever way utm hangs: float32 keeps its centimetres there.
        assert_eq!(nav2["frame"], "map", "{name}");
        let pgm = std::fs::read(dir.path().join(format!("{name}.pgm"))).unwrap();
        let text = std::fs::read_to_string(&yaml).unwrap();
        maps.push((pgm, parse_yaml(&text)));
        let world_file = dir.path().join(format!("{name}.pgmw"));
        if place.is_none() {
            assert!(nav2["georeference"].is_null());
            assert!(!world_file.exists());
            continue;
        }
        let georeference = &nav2["georeference"];
        assert_eq!(georeference["frame"], "utm", "{name}");
        let origin: Vec<f64> = serde_json::from_value(georeference["origin_m"].clone()).unwrap();
        for (got, want) in origin.iter().zip([512_000.5, 4_100_000.25, 30.0]) {
            assert!((got - want).abs() < 1e-6, "{name}: {origin:?}");
        }
        assert!(text.contains("`utm`"), "{text}");
        assert_eq!(
            nav2["gis_files"],
            serde_json::json!([world_file.to_str().unwrap()]),
            "a log names no CRS: no .prj"
        );
        // The world file: each pixel's centre in utm, rotated with the map.
        let numbers: Vec<f64> = std::fs::read_to_string(&world_file)
            .unwrap()
            .lines()
            .map(|l| l.parse().unwrap())
            .collect();
        let resolution = nav2["resolution_m"].as_f64().unwrap();
        let height = nav2["height"].as_f64().unwrap();
        let origin_xy: Vec<f64> = serde_json::from_value(nav2["origin"].clone()).unwrap();
        let pixel_in_utm = |col: f64, row: f64| {
            let in_map = nalgebra::Point3::new(
                origin_xy[0] + (col + 0.5) * resolution,
                origin_xy[1] + (height - row - 0.5) * resolution,
                0.0,
            );
            utm_from_map * in_map
        };
        let by_world_file = |col: f64, row: f64| {
            [
                numbers[0] * col + numbers[2] * row + numbers[4],
                numbers[1] * col + numbers[3] * row + numbers[5],
            ]
        };
        for (col, row) in [(0.0, 0.0), (10.0, 0.0), (0.0, 7.0), (123.0, 45.0)] {
            let want = pixel_in_utm(col, row);
            let got = by_world_file(col, row);
            assert!(
                (got[0] - want.x).abs() < 1e-6 && (got[1] - want.y).abs() < 1e-6,
                "{name}: pixel ({col}, {row}) at {got:?}, expected ({}, {})",
                want.x,
                want.y
            );
        }
    }
    // The map itself is the same whether or not, and however, utm is there.
    for (pgm, yaml) in &maps[1..] {
        assert!(pgm == &maps[0].0);
        assert_eq!(yaml["origin"], maps[0].1["origin"]);
    }
}

/// `--nav2 site.pgm` (the image's name, not the YAML's) is a usage error saying
/// what to give (it said "site.pgm and site.pgm name the same file").
#[test]
fn nav2_given_the_images_name_says_to_give_the_yaml() {
    let Some(sample) = crate::common::sample() else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let (map, pgm) = (dir.path().join("m.png"), dir.path().join("site.pgm"));
    let args = [
        "map",
        crate::common::arg(&sample),
        "-o",
        crate::common::arg(&map),
        "--nav2",
        crate::common::arg(&pgm),
    ];
    let err = crate::common::usage_error(crate::common::travmap(&args));
    crate::common::assert_contains(&err, &["--nav2 takes the map's YAML", "site.yaml"]);
}
