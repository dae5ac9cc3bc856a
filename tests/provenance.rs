//! Every output says which model made it and how (issue "says what it used"): broken
//! model files refused, the model chosen recorded in every configuration echoed, the
//! fit notice's advice one that the command and the drive can follow, notices said
//! once, and dataset folders that hold only what travmap wrote.

use std::path::Path;

use crate::common::{
    arg, assert_contains, clean_failure, json_summary, sample, shared_data, stderr, stdout,
    success, travmap, travmap_metadata, usage_error, write_output,
};
use serde_json::Value;

fn read_json(path: &Path) -> Value {
    serde_json::from_slice(&std::fs::read(path).unwrap()).unwrap()
}

/// The key-value metadata of a Parquet file.
fn parquet_metadata(path: &Path) -> std::collections::BTreeMap<String, String> {
    use parquet::file::reader::{FileReader, SerializedFileReader};
    let reader = SerializedFileReader::new(std::fs::File::open(path).unwrap()).unwrap();
    let metadata = reader.metadata().file_metadata().key_value_metadata();
    (metadata.into_iter().flatten())
        .map(|kv| (kv.key.clone(), kv.value.clone().unwrap_or_default()))
        .collect()
}

/// The embedded road model written to `dir/name` with `edit` applied.
fn edited_model(dir: &Path, name: &str, edit: impl Fn(&mut Value)) -> std::path::PathBuf {
    let path = dir.join(name);
    let sample = sample().unwrap();
    // A model file of the road model: adapt unchecked writes one, kept prior aside;
    // cheaper, the prior kept by a drive too short writes the prior itself.
    write_output(
        "adapt",
        &sample,
        &path,
        &["--frames", "0", "--set", "adapt.min_footprint_cells=100000"],
    );
    let mut model = read_json(&path);
    edit(&mut model);
    std::fs::write(&path, model.to_string()).unwrap();
    path
}

/// A change to a model file's JSON.
type Edit = dyn Fn(&mut Value);

/// Regression (item 1): a gamma of 1e300, no support vectors, and a rho that no
/// kernel sum outweighs were used with exit 0.
#[test]
fn broken_model_files_are_refused_naming_the_file_and_the_fault() {
    let Some(sample) = sample() else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let cases: [(&str, &Edit, &str); 4] = [
        (
            "gamma.json",
            &|m| m["gamma"] = 1e300.into(),
            "`gamma` is 1e300, beyond the range",
        ),
        (
            "empty.json",
            &|m| {
                m["support_vectors"] = serde_json::json!([]);
                m["dual_coefficients"] = serde_json::json!([]);
                m["check_cells"] = Value::Null;
            },
            "no support vectors",
        ),
        (
            "rho.json",
            &|m| m["rho"] = 1e30.into(),
            "every cell would be called not traversable",
        ),
        (
            "edited.json",
            &|m| m["gamma"] = 0.5.into(),
            "do not decide the cells stored with it",
        ),
    ];
    for (name, edit, expected) in cases {
        let model = edited_model(dir.path(), name, edit);
        let err = clean_failure(travmap(&["eval", arg(&sample), "--model", arg(&model)]));
        assert_contains(&err, &[expected, name]);
        // --json names the file.
        let output = travmap(&["run", arg(&sample), "--model", arg(&model), "--json"]);
        let record: Value = serde_json::from_str(stderr(&output).lines().last().unwrap()).unwrap();
        assert_eq!(record["file"], arg(&model), "{record}");
    }
    // A name of nothing is a usage error, not "No such file".
    let err = usage_error(travmap(&["run", arg(&sample), "--model", ""]));
    assert_contains(&err, &["road, offroad or a model file's path expected"]);
}

/// Regression (item 2): with --model offroad every output recorded "road".
#[test]
fn every_output_records_the_model_it_used() {
    let Some(sample) = sample() else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let frames = ["--frames", "0..2"];
    let summary =
        json_summary(&[&["eval", arg(&sample), "--model", "offroad"][..], &frames].concat());
    assert_eq!(summary["config"]["classifier"]["model"], "offroad");
    assert_eq!(summary["model"]["name"], "embedded offroad model");
    assert_eq!(summary["model"]["rule"], "offroad");
    // The annotated MCAP's metadata.
    let annotated = dir.path().join("a.mcap");
    write_output(
        "annotate",
        &sample,
        &annotated,
        &[&["--model", "offroad"][..], &frames].concat(),
    );
    let metadata = travmap_metadata(&std::fs::read(&annotated).unwrap());
    let config: Value = serde_json::from_str(&metadata["config"]).unwrap();
    assert_eq!(config["classifier"]["model"], "offroad");
    assert_eq!(metadata["model_rule"], "offroad");
    assert_eq!(metadata["model"], "embedded offroad model");
    // The cell table's, with the model that predicted its cells.
    let cells = dir.path().join("cells.parquet");
    write_output(
        "dataset",
        &sample,
        &cells,
        &[&["--model", "offroad"][..], &frames].concat(),
    );
    let metadata = parquet_metadata(&cells);
    let config: Value = serde_json::from_str(&metadata["travmap.config"]).unwrap();
    assert_eq!(config["classifier"]["model"], "offroad");
    let model: Value = serde_json::from_str(&metadata["travmap.model"]).unwrap();
    assert_eq!(model["rule"], "offroad");
    assert_eq!(model["sha256"].as_str().unwrap().len(), 64);
    // The fused map's cells.
    let map_cells = dir.path().join("map.parquet");
    success(travmap(&[
        "map",
        arg(&sample),
        "--cells",
        arg(&map_cells),
        "--model",
        "offroad",
        "-q",
        "--frames",
        "0..2",
    ]));
    let model: Value =
        serde_json::from_str(&parquet_metadata(&map_cells)["travmap.model"]).unwrap();
    assert_eq!(model["name"], "embedded offroad model");
    // A model `adapt -o` writes records the prior it was adapted from.
    let adapted = dir.path().join("adapted.json");
    write_output(
        "adapt",
        &sample,
        &adapted,
        &["--model", "offroad", "--set", "adapt.check=false"],
    );
    assert_eq!(
        read_json(&adapted)["config"]["classifier"]["model"],
        "offroad"
    );
    // Text output names the model: render, map, annotate.
    let picture = dir.path().join("f.png");
    let out = success(travmap(&[
        "render",
        arg(&sample),
        "--frame",
        "2",
        "-o",
        arg(&picture),
        "--model",
        "offroad",
    ]));
    assert_contains(&out, &["model: embedded offroad model (sha256 "]);
    // --model beats --set classifier.model, said once.
    let output = travmap(&[
        "run",
        arg(&sample),
        "--frames",
        "0",
        "--model",
        "offroad",
        "--set",
        "classifier.model=road",
        "-q",
    ]);
    success(output.clone());
    let said = "notice: --model offroad is used, not the --set classifier.model=road";
    assert_eq!(
        stderr(&output).matches(said).count(),
        1,
        "{}",
        stderr(&output)
    );
}

/// Regression (item 8): a model path in a config file was read from the current
/// folder, and its error did not name the config.
#[test]
fn a_config_files_model_is_read_from_its_folder() {
    let Some(sample) = sample() else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let robot = dir.path().join("robot");
    std::fs::create_dir(&robot).unwrap();
    write_output(
        "adapt",
        &sample,
        &robot.join("m.json"),
        &["--frames", "0", "--set", "adapt.min_footprint_cells=100000"],
    );
    let config = robot.join("robot.toml");
    std::fs::write(&config, "[classifier]\nmodel = \"m.json\"\n").unwrap();
    // Run from another folder: the model is the config's neighbour.
    let summary = json_summary(&[
        "eval",
        arg(&sample),
        "--frames",
        "0",
        "--config",
        arg(&config),
    ]);
    let name = summary["model"]["name"].as_str().unwrap();
    assert!(name.ends_with("robot/m.json"), "{name}");
    std::fs::write(&config, "[classifier]\nmodel = \"gone.json\"\n").unwrap();
    let err = clean_failure(travmap(&[
        "run",
        arg(&sample),
        "--frames",
        "0",
        "--config",
        arg(&config),
    ]));
    assert_contains(
        &err,
        &[
            "the model of classifier.model = ",
            "robot.toml",
            "gone.json",
        ],
    );
}

/// Regression (item 3): the notice advised --adapt where the command has none and the
/// drive is one scan, claimed training drives stay under 30 %, and went to stdout
/// (eval) or nowhere (--json).
#[test]
fn the_fit_notice_advises_what_can_be_done_on_stderr_in_every_mode() {
    let Some(rellis) = shared_data("rellis3d-000104/sequences/00") else {
        return;
    };
    let labels = ["--set", "ground_truth.labels=\"rellis3d\""];
    for command in ["run", "eval"] {
        for json in [false, true] {
            let mut args = [&[command, arg(&rellis)][..], &labels].concat();
            if json {
                args.push("--json");
            }
            let output = travmap(&args);
            success(output.clone());
            let (out, err) = (stdout(&output), stderr(&output));
            assert!(!out.contains("notice:"), "{command} {json}: {out}");
            assert_eq!(
                err.matches("these drives fit the model poorly").count(),
                1,
                "{command} {json}: {err}"
            );
            // One scan shows no footprint: adapting is no remedy; the other rule's
            // model is, said with what it changes.
            assert!(
                !err.contains("--adapt") && !err.contains("travmap adapt"),
                "{err}"
            );
            assert_contains(
                &err,
                &["--model offroad", "calls them traversable", "over 30 %"],
            );
            assert!(!err.contains("its training drives: at most"), "{err}");
        }
    }
    // eval knows the scan is one of the model's own: more teaching is no remedy.
    let err = stderr(&travmap(&[&["eval", arg(&rellis)][..], &labels].concat()));
    assert_contains(&err, &["1 of these frames was among its training scans"]);
    assert!(!err.contains("travmap train"), "{err}");
}

/// Regression (item 4): `eval --adapt` printed each input notice twice.
#[test]
fn adapting_first_says_each_notice_once() {
    let Some(more) = shared_data("semantickitti-00-more/sequences/00") else {
        return;
    };
    let output = travmap(&["eval", arg(&more), "--adapt"]);
    success(output.clone());
    let err = stderr(&output);
    let mut lines: Vec<&str> = err.lines().collect();
    let count = lines.len();
    lines.sort_unstable();
    lines.dedup();
    assert_eq!(lines.len(), count, "{err}");
    assert!(
        count >= 2,
        "the drive's notices and the check's verdict: {err}"
    );
}

/// Regression (items 5 and 6): the adapted model's hash differed between two
/// identical runs; a drive without labels was adapted to before eval said so.
#[test]
fn the_same_adaptation_gives_the_same_model_and_eval_checks_labels_first() {
    let Some(sample) = sample() else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let hashes: Vec<Value> = (0..2)
        .map(|i| {
            let path = dir.path().join(format!("a{i}.json"));
            let summary = json_summary(&[
                "adapt",
                arg(&sample),
                "-o",
                arg(&path),
                "--set",
                "adapt.check=false",
                "--frames",
                "0..4",
            ]);
            summary["model"]["sha256"].clone()
        })
        .collect();
    assert_eq!(hashes[0], hashes[1]);
    // A drive without labels: refused before adapting.
    let unlabelled = crate::common::without_labels(&sample, dir.path());
    let err = clean_failure(travmap(&["eval", arg(&unlabelled), "--adapt"]));
    assert_contains(&err, &["no frame of the input has labels"]);
    assert!(
        !err.contains("the prior is kept") && !err.contains("replaces the prior"),
        "{err}"
    );
}

/// Regression (item 7): `dataset -o DIR/` deleted a part file it did not write, and
/// left other Parquet files that then joined the table.
#[test]
fn a_dataset_folder_holds_only_what_travmap_wrote() {
    let Some(sample) = sample() else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let folder = dir.path().join("cells");
    std::fs::create_dir(&folder).unwrap();
    let foreign = folder.join("part-00007.parquet");
    std::fs::write(&foreign, b"someone else's").unwrap();
    let out_dir = format!("{}/", folder.display());
    let err = clean_failure(travmap(&[
        "dataset",
        arg(&sample),
        "-o",
        &out_dir,
        "--frames",
        "0..2",
    ]));
    assert_contains(&err, &["part-00007.parquet", "did not write"]);
    assert!(foreign.exists());
    std::fs::remove_file(&foreign).unwrap();
    // Written twice, the second with fewer parts: the first's extra parts go, the
    // manifest lists what is there.
    success(travmap(&[
        "dataset",
        arg(&sample),
        "-o",
        &out_dir,
        "--rows-per-part",
        "1",
        "-q",
        "--frames",
        "0..3",
    ]));
    success(travmap(&[
        "dataset",
        arg(&sample),
        "-o",
        &out_dir,
        "-q",
        "--frames",
        "0..3",
    ]));
    let manifest = read_json(&folder.join("_travmap_dataset.json"));
    assert_eq!(manifest["parts"], serde_json::json!(["part-00000.parquet"]));
    let mut names: Vec<String> = std::fs::read_dir(&folder)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    assert_eq!(names, ["_travmap_dataset.json", "part-00000.parquet"]);
}

/// Regression (item 8): crossval's fit was always 0 cells.
#[test]
fn crossval_measures_the_fit_of_its_held_out_cells() {
    let Some(sample) = sample() else {
        return;
    };
    let summary = json_summary(&["crossval", arg(&sample), "-q"]);
    let cells = summary["fit"]["cells"].as_u64().unwrap();
    let unsure = summary["fit"]["unsure_cells"].as_u64().unwrap();
    assert!(
        cells > 0 && unsure > 0 && unsure < cells,
        "{}",
        summary["fit"]
    );
}
