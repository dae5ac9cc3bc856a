//! `travmap dataset`: the Parquet rows match the pipeline's own values cell by cell
//! (read back with pyarrow, the reader most users will have, and checked against
//! DuckDB and Polars), `train` learns the same model from the Parquet file as from
//! the sequence itself, and reads the same rows from the file as rewritten by
//! pyarrow (every codec), DuckDB and Polars.

use std::path::Path;

use serde_json::Value;
use travmap_io::{Source, SourceOptions};
use travmap_method::classifier::SvmModel;
use travmap_method::grid::CellClass;
use travmap_outputs::dataset::reading::{Labels, read_training_rows};
use travmap_run::DriveRun;
use travmap_training::TrainingSet;

use crate::common::{arg, assert_contains, clean_failure, json_summary, travmap, with_settings};

/// A grid search small enough for a test (`--set` settings): the point is the comparison.
const QUICK_TRAINING: [&str; 3] = [
    "training.c_values=[10.0]",
    "training.gamma_values=[0.05]",
    "training.folds=2",
];

/// `travmap dataset <seq> -o <out> <extra...> --json`: its summary.
fn dataset(seq: &Path, out: &Path, extra: &[&str]) -> Value {
    json_summary(&[&["dataset", arg(seq), "-o", arg(out)][..], extra].concat())
}

/// The error of `travmap train <input> -o <model>`, which must fail cleanly.
fn train_error(input: &Path, model: &Path, extra: &[&str]) -> String {
    let mut args = vec!["train", arg(input), "-o", arg(model)];
    args.extend(extra);
    clean_failure(travmap(&args))
}

/// The shipped sample and the Python that has pyarrow, DuckDB and Polars; None (the
/// reason printed) without either.
fn sample_and_client() -> Option<(std::path::PathBuf, String)> {
    let seq = crate::common::sample()?;
    let python = crate::common::env_var(
        "TRAVMAP_CLIENT_PYTHON",
        "a Python with pyarrow, duckdb and polars",
    )?;
    Some((seq, python))
}

#[test]
#[ignore = "needs the real clients: source .ci/clients.sh, then cargo test --release -- --ignored"]
fn rows_match_the_pipeline_cell_by_cell_in_pyarrow_duckdb_and_polars() {
    let Some((seq, python)) = sample_and_client() else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let model_path = dir.path().join("model.json");
    let model = SvmModel::embedded(travmap_core::config::LabelRule::Road).unwrap();
    std::fs::write(&model_path, model.to_json()).unwrap();
    let cells = dir.path().join("cells.parquet");
    let summary = dataset(&seq, &cells, &["--model", arg(&model_path)]);
    assert_eq!(summary["frames"], 6);

    let frame = 1;
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/clients/read_parquet.py");
    let rewrites = dir.path().join("rewrites");
    std::fs::create_dir(&rewrites).unwrap();
    let out = crate::common::run_client(
        std::process::Command::new(&python)
            .arg(&script)
            .arg(&cells)
            .arg(frame.to_string())
            .arg(&rewrites),
    );
    let read: Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(read["rows"], summary["rows"]);
    assert_eq!(
        read["metadata_keys"],
        serde_json::json!([
            "travmap.config",
            "travmap.format",
            "travmap.labelled_scans",
            "travmap.model"
        ])
    );
    let columns = read["columns"].as_array().unwrap();
    assert_eq!(
        columns.len(),
        8 + 20 + 3 + 88 + 4,
        "+ 3 remission columns, the labels, footprint and pseudo_label"
    );
    assert_eq!(columns[8], serde_json::json!(["linearity", "float"]));
    assert_eq!(columns[2], serde_json::json!(["stamp_ns", "int64"]));
    // The script has checked that DuckDB and Polars read every row as pyarrow does.
    assert_eq!(read["duckdb_metadata_keys"], read["metadata_keys"]);
    let polars_types = read["polars_types"].as_array().unwrap();
    assert_eq!(polars_types[8], "Float32");
    assert_eq!(polars_types[columns.len() - 1], "Boolean");

    // The same frame through the library, on the training grid the command uses.
    let mut config = travmap_core::Config::default();
    config.grid.size_m = config.training.grid_size_m;
    let source = Source::open(&seq, &SourceOptions::default(), &|_| {}).unwrap();
    let mut selection = DriveRun::new(source, frame..frame + 1);
    selection.follow_trajectory(&config).unwrap();
    let mut results = Vec::new();
    selection
        .run::<travmap_core::Error>(&config, Some(&model), |r| {
            results.push(r);
            Ok(())
        })
        .unwrap();
    let result = &results[0];
    let rows = read["frame_rows"].as_array().unwrap();
    let predictable: Vec<usize> = (0..result.layout.cell_count())
        .filter(|&c| result.features.predictable[c])
        .collect();
    assert_eq!(rows.len(), predictable.len());
    let as_bool = |class: CellClass| match class {
        CellClass::Traversable => Value::Bool(true),
        CellClass::NonTraversable => Value::Bool(false),
        CellClass::Unknown => Value::Null,
    };
    for (row, &cell) in rows.iter().zip(&predictable) {
        let (col, grid_row) = result.layout.col_row(cell);
        let [x, y] = result.layout.cell_centre_in_world(cell);
        assert_eq!(row["row"], grid_row);
        assert_eq!(row["col"], col);
        assert_eq!(row["x_m"].as_f64().unwrap(), x);
        assert_eq!(row["y_m"].as_f64().unwrap(), y);
        assert_eq!(row["stamp_ns"], result.stamp_ns);
        assert_eq!(row["points"], result.cells.point_count(cell));
        for (name, &value) in travmap_method::features::FEATURE_NAMES
            .iter()
            .zip(result.features.cell(cell))
        {
            // float32 -> Python float -> JSON -> f64 -> f32 is exact.
            assert_eq!(row[*name].as_f64().unwrap() as f32, value, "{name}");
        }
        assert_eq!(row["hue_0"], Value::Null, "no camera in this sequence");
        let truth = result.ground_truth.as_ref().unwrap()[cell];
        assert_eq!(row["ground_truth_traversable"], as_bool(truth));
        let predicted = result.filtered.as_ref().unwrap()[cell];
        assert_eq!(row["predicted_traversable"], as_bool(predicted));
        let (footprint, _) = result.footprint.as_ref().unwrap();
        assert_eq!(row["footprint"], footprint[cell]);
        let pseudo = result.self_labels.as_ref().unwrap()[cell];
        assert_eq!(row["pseudo_label"], pseudo.map_or(Value::Null, Value::Bool));
    }

    // What other writers make of the file trains on the same rows.
    let training_rows = |path: &Path| {
        let mut set = TrainingSet::default();
        read_training_rows(path, &config, &mut set, Labels::GroundTruth).map(|_| set)
    };
    let ours = training_rows(&cells).unwrap();
    assert!(ours.len() > 10_000, "{} labelled rows", ours.len());
    for writer in [
        "pyarrow-none",
        "pyarrow-snappy",
        "pyarrow-gzip",
        "pyarrow-brotli",
        "pyarrow-lz4",
        "duckdb",
        "polars",
    ] {
        let theirs = training_rows(&rewrites.join(format!("{writer}.parquet")))
            .unwrap_or_else(|e| panic!("{writer}: {e}"));
        assert_eq!(theirs.features, ours.features, "{writer}");
        assert_eq!(theirs.traversable, ours.traversable, "{writer}");
        assert_eq!(theirs.centre_in_world, ours.centre_in_world, "{writer}");
        assert_eq!(theirs.appearance_row, ours.appearance_row, "{writer}");
    }
    let err = training_rows(&rewrites.join("polars-null-x_m.parquet"))
        .unwrap_err()
        .to_string();
    assert_contains(
        &err,
        &["polars-null-x_m.parquet", "column `x_m` is null in row 0"],
    );
}

#[test]
fn training_on_the_parquet_file_gives_the_model_training_on_the_sequence_gives() {
    let Some(seq) = crate::common::sample() else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let cells = dir.path().join("cells.parquet");
    dataset(&seq, &cells, &[]);
    let train = |input: &Path, name: &str| -> Value {
        let model = dir.path().join(name);
        let quick = crate::common::with_settings(&[], &QUICK_TRAINING);
        crate::common::write_output("train", input, &model, &quick);
        let mut doc: Value = serde_json::from_slice(&std::fs::read(&model).unwrap()).unwrap();
        let strip = |part: &mut Value| {
            let training = part["training"].as_object_mut().unwrap();
            training.remove("sources");
            training.remove("seconds");
            // A dataset holds cells, not the scans they came from.
            training.remove("frame_sha256");
        };
        strip(&mut doc);
        strip(&mut doc["fallback"]);
        doc
    };
    let from_parquet = train(&cells, "parquet.json");
    let from_sequence = train(&seq, "sequence.json");
    assert_eq!(from_parquet["training"]["samples"], 13111);
    assert!(
        from_parquet == from_sequence,
        "the models differ beyond their sources and timings"
    );
}

#[test]
fn datasets_from_other_settings_or_other_writers_are_refused() {
    let Some(seq) = crate::common::sample() else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let cells = dir.path().join("coarse.parquet");
    dataset(
        &seq,
        &cells,
        &["--frames", "0..1", "--set", "features.curvity_bins=80"],
    );
    let model = dir.path().join("m.json");
    let err = train_error(&cells, &model, &[]);
    assert_contains(
        &err,
        &["coarse.parquet", "extracted with other feature settings"],
    );
    let not_parquet = dir.path().join("junk.parquet");
    std::fs::write(&not_parquet, b"not a parquet file at all").unwrap();
    let err = train_error(&not_parquet, &model, &[]);
    assert_contains(&err, &["junk.parquet"]);
    assert!(!model.exists(), "no model is written on failure");
}

#[test]
fn corrupt_datasets_are_errors_naming_the_file_not_panics() {
    // Inputs on which the parquet crate panics (found by the dataset_file fuzz target).
    let regressions = Path::new(env!("CARGO_MANIFEST_DIR")).join("fuzz/regressions/dataset_file");
    let dir = tempfile::tempdir().unwrap();
    let model = dir.path().join("m.json");
    for (name, panic) in [
        (
            "negative-column-start.parquet",
            "column start and length should not be negative, at parquet-60.1.0/src/file/metadata/mod.rs",
        ),
        (
            "dictionary-decoder-never-set.parquet",
            "Decoder for dict should have been set",
        ),
        (
            "byte-stream-split-out-of-bounds.parquet",
            "index out of bounds",
        ),
    ] {
        // Written before feature groups existed: the paper's 20 features.
        let paper = ["--set", "features.groups=[]"];
        let err = train_error(&regressions.join(name), &model, &paper);
        assert_contains(&err, &[name, "corrupt Parquet file", panic]);
        assert!(!model.exists());
    }
}

/// The cells of `seq` written into the folder `dir` as parts of at most about
/// `rows` rows (whole frames each).
fn dataset_parts(seq: &Path, dir: &Path, rows: &str) -> Value {
    let folder = format!("{}/", dir.display());
    json_summary(&["dataset", arg(seq), "-o", &folder, "--rows-per-part", rows])
}

#[test]
fn a_folder_gets_part_files_of_whole_frames_that_train_as_the_single_file() {
    let Some(seq) = crate::common::sample() else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let single = dir.path().join("cells.parquet");
    let one = dataset(&seq, &single, &[]);
    let folder = dir.path().join("cells");
    // About 4,500 rows a frame: a part closes at the frame that reaches 5,000 rows.
    let parts = dataset_parts(&seq, &folder, "5000");
    assert_eq!(parts["rows"], one["rows"]);
    let files: Vec<String> = (parts["outputs"].as_array().unwrap().iter())
        .map(|f| f.as_str().unwrap().to_string())
        .collect();
    let names: Vec<String> = std::fs::read_dir(&folder)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|name| name != "_travmap_dataset.json")
        .collect();
    assert!(files.len() >= 3, "{files:?}");
    assert_eq!(
        names.len(),
        files.len(),
        "nothing but the parts and their list: {names:?}"
    );
    for (index, file) in files.iter().enumerate() {
        assert!(
            file.ends_with(&format!("part-{index:05}.parquet")),
            "{file}"
        );
    }
    // The folder trains on the very rows of the single file.
    let config = travmap_core::Config::default();
    let rows = |path: &Path| {
        let mut set = TrainingSet::default();
        read_training_rows(path, &config, &mut set, Labels::GroundTruth).unwrap();
        set
    };
    let (from_file, from_parts) = (rows(&single), rows(&folder));
    assert_eq!(from_parts.features, from_file.features);
    assert_eq!(from_parts.traversable, from_file.traversable);
    assert_eq!(from_parts.centre_in_world, from_file.centre_in_world);
    let model = dir.path().join("m.json");
    let trained = json_summary(&with_settings(
        &["train", arg(&folder), "-o", arg(&model)],
        &QUICK_TRAINING,
    ));
    assert_eq!(trained["cells"], from_file.len());
    assert_eq!(trained["inputs"][0]["path"], arg(&folder));
    // Written again in fewer parts, the folder holds only the new ones.
    let again = dataset_parts(&seq, &folder, "1000000");
    assert_eq!(again["outputs"].as_array().unwrap().len(), 1);
    // The part and the manifest that lists it.
    assert_eq!(std::fs::read_dir(&folder).unwrap().count(), 2);
    // A folder of something else is no dataset.
    let mut set = TrainingSet::default();
    let err = read_training_rows(dir.path(), &config, &mut set, Labels::GroundTruth)
        .unwrap_err()
        .to_string();
    assert_contains(&err, &["without part-NNNNN.parquet files"]);
}

#[test]
#[ignore = "needs the real clients: source .ci/clients.sh, then cargo test --release -- --ignored"]
fn pyarrow_duckdb_and_polars_read_the_parts_as_one_table() {
    let Some((seq, python)) = sample_and_client() else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let single = dir.path().join("cells.parquet");
    dataset(&seq, &single, &[]);
    let folder = dir.path().join("cells");
    let parts = dataset_parts(&seq, &folder, "5000");
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/clients/read_parquet_parts.py");
    let out = crate::common::run_client(
        std::process::Command::new(&python)
            .arg(&script)
            .arg(&folder)
            .arg(&single),
    );
    let read: Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(read["rows"], parts["rows"]);
    assert_eq!(read["parts"], parts["outputs"].as_array().unwrap().len());
}
