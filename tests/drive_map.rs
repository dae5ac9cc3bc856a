//! `travmap map`: the fused drive map's picture cell by cell against the library's
//! fusion, its Parquet table, its memory on a long drive, and how often annotate
//! writes it.

use std::path::Path;

use crate::common::{arg, success, travmap, write_output};
use travmap_outputs::drive_map::MapPicture;
use travmap_outputs::figure::panel_origin;
use travmap_outputs::palette::Palette;

#[test]
fn the_picture_shows_the_fused_map_truth_and_errors_cell_by_cell() {
    let Some(seq) = crate::common::sample() else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let png = dir.path().join("drive.png");
    let cells_path = dir.path().join("cells.parquet");
    write_output(
        "map",
        &seq,
        &png,
        &["--cell-pixels", "8", "--cells", arg(&cells_path)],
    );
    let image = crate::common::read_png(&png);
    let cells = crate::common::fused_drive(&seq);
    let picture = MapPicture::of(&cells, 8);
    let panel = picture.cells[0] as u32 * 8;
    let (last_x, _) = panel_origin(2, panel);
    assert!(image.width >= last_x + panel);
    let palette = Palette::SAFE;
    // Most of a cell's 64 pixels: the trajectory and the axes are drawn over some.
    let mostly = |panel_index: usize, x: u32, y: u32, expected: [u8; 3]| {
        let (x0, y0) = panel_origin(panel_index, panel);
        let mut matching = 0;
        for y in y0 + y..y0 + y + 8 {
            for x in x0 + x..x0 + x + 8 {
                let at = 3 * (y * image.width + x) as usize;
                matching += (image.rgb[at..at + 3] == expected) as usize;
            }
        }
        matching >= 40
    };
    let mut errors = 0;
    for cell in &cells {
        let (x, y) = picture.cell_origin_px(cell.key);
        assert!(
            mostly(0, x, y, palette.class(cell.class)),
            "prediction, {cell:?}"
        );
        assert!(
            mostly(1, x, y, palette.class(cell.ground_truth)),
            "truth, {cell:?}"
        );
        let error = palette.error(cell.class, cell.ground_truth);
        errors +=
            (error == palette.false_traversable || error == palette.false_not_traversable) as usize;
        assert!(mostly(2, x, y, error), "errors, {cell:?}");
    }
    assert!(errors > 0, "the picture shows some errors");

    // The Parquet table: one row per fused cell.
    use parquet::file::reader::{FileReader, SerializedFileReader};
    let reader = SerializedFileReader::new(std::fs::File::open(&cells_path).unwrap()).unwrap();
    let metadata = reader.metadata();
    assert_eq!(metadata.file_metadata().num_rows() as usize, cells.len());
    let names: Vec<&str> = metadata
        .file_metadata()
        .schema_descr()
        .columns()
        .iter()
        .map(|c| c.name())
        .collect();
    assert_eq!(
        names,
        [
            "x_m",
            "y_m",
            "evidence",
            "probability",
            "observations",
            "predicted_traversable",
            "ground_truth_traversable"
        ]
    );
}

#[test]
fn the_fused_map_scores_at_least_as_well_as_the_frames() {
    let Some(seq) = crate::common::sample() else {
        return;
    };
    let json = crate::common::json_summary(&["eval", arg(&seq)]);
    let per_frame = &json["scores"];
    let fused = &json["drive_map"]["scores"];
    eprintln!("per frame {per_frame}\nfused {fused}");
    for score in ["accuracy", "miou"] {
        assert!(
            fused[score].as_f64().unwrap() >= per_frame[score].as_f64().unwrap(),
            "{score}: fused {fused}, per frame {per_frame}"
        );
    }
}

#[test]
fn a_long_drive_costs_memory_in_proportion_to_its_area() {
    let Some(seq) = crate::common::sample() else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let long = crate::common::long_sequence(Path::new(&seq), dir.path(), 600);
    let png = dir.path().join("long.png");
    let output = travmap(&["map", arg(&long), "-o", arg(&png), "--json"]);
    let (_, summary) = crate::common::json_records(&success(output));
    let (memory, seen, area) = (
        summary["memory_bytes"].as_f64().unwrap(),
        summary["seen_cells"].as_f64().unwrap(),
        summary["area_m2"].as_f64().unwrap(),
    );
    eprintln!("600 frames: {seen} cells seen, {area:.0} m2, map {memory:.0} bytes");
    assert_eq!(summary["frames"], 600);
    // A 32 x 32-cell tile costs 20 KiB: within a few tiles' fill of the area seen,
    // and far below the bounding box of a drive that turns.
    assert!(
        memory / seen < 200.0,
        "{} bytes per seen cell",
        memory / seen
    );
}

#[test]
fn annotate_writes_the_drive_map_as_often_as_asked_and_always_the_final_one() {
    let dir = tempfile::tempdir().unwrap();
    let maps = |every: &str| {
        let flags = ["--no-passthrough", "--drive-map-every", every];
        let (_, out) = crate::common::sample_annotated(dir.path(), &flags)?;
        let bytes = std::fs::read(&out).unwrap();
        let stamps_of = |topic: &str| -> Vec<(u64, Vec<u8>)> {
            mcap::MessageStream::new(&bytes)
                .unwrap()
                .map(|m| m.unwrap())
                .filter(|m| m.channel.topic == topic)
                .map(|m| (m.log_time, m.data.to_vec()))
                .collect()
        };
        let frames: Vec<u64> = stamps_of("/travmap/prediction")
            .into_iter()
            .map(|(stamp, _)| stamp)
            .collect();
        Some((frames, stamps_of("/travmap/drive_map")))
    };
    let Some((frames, every_two)) = maps("2") else {
        return;
    };
    assert_eq!(frames.len(), 6);
    // After frames 2, 4 and 6: the last is the final map, not written twice.
    let stamps: Vec<u64> = every_two.iter().map(|(stamp, _)| *stamp).collect();
    assert_eq!(stamps, [frames[1], frames[3], frames[5]]);
    let (_, only_final) = maps("0").unwrap();
    assert_eq!(only_final.len(), 1);
    assert_eq!(only_final[0], every_two[2]);
    // Every 4: after frame 4, and the final map after frame 6.
    let (_, every_four) = maps("4").unwrap();
    let stamps: Vec<u64> = every_four.iter().map(|(stamp, _)| *stamp).collect();
    assert_eq!(stamps, [frames[3], frames[5]]);
    assert_eq!(every_four[1], every_two[2]);
}
