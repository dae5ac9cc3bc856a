//! The binary on the real SemanticKITTI sample: the first-run commands, training,
//! evaluation, cross-validation and configuration.

use std::path::Path;

use crate::common::{
    arg, assert_contains, clean_failure, json_summary, success, travmap, write_output,
};
use serde_json::Value;

/// The shipped sample's path as an argument.
fn sample() -> Option<String> {
    crate::common::sample().map(|p| p.display().to_string())
}

/// The search grid of the quick training runs of these tests (`--set` settings).
const QUICK: [&str; 2] = ["training.c_values=[10.0]", "training.gamma_values=[0.05]"];

/// `args` followed by the quick search grid.
fn quick<'a>(args: &[&'a str]) -> Vec<&'a str> {
    crate::common::with_settings(args, &QUICK)
}

#[test]
fn eval_with_no_flags_prints_the_papers_table() {
    let Some(seq) = sample() else { return };
    let out = success(travmap(&["eval", &seq]));
    for column in [
        "Acc",
        "mIoU",
        "F1",
        "FPR",
        "TPR",
        "FNR",
        "TNR",
        "latency",
        "travmap (filtered)",
        "paper, geometry only",
    ] {
        assert!(out.contains(column), "missing {column}:\n{out}");
    }
    assert!(out.contains("over 3 frames"), "{out}");
    assert!(out.contains("embedded road model"), "{out}");
    // The model line names the datasets it learnt from, not the folder it was built in.
    let model = out.lines().find(|l| l.starts_with("model:")).unwrap();
    assert_contains(
        model,
        &[
            "semantickitti.parquet",
            "rellis3d.parquet",
            "nuscenes.parquet",
        ],
    );
    assert!(!model.contains("target/"), "{model}");
}

#[test]
fn eval_json_reports_config_model_and_scores() {
    let Some(seq) = sample() else { return };
    let doc = json_summary(&["eval", &seq, "--frames", "0..3", "--set", "grid.size_m=16"]);
    assert_eq!(doc["config"]["grid"]["size_m"], 16.0);
    assert_eq!(doc["config"]["integration"]["scans"], 3);
    assert_eq!(doc["scored_frames"], 3);
    assert_eq!(doc["model"]["sha256"].as_str().unwrap().len(), 64);
    let accuracy = doc["scores"]["accuracy"].as_f64().unwrap();
    assert!((0.5..=1.0).contains(&accuracy), "{accuracy}");
    let c = &doc["confusion"];
    let cells: u64 = ["tp", "tn", "fp", "fn", "unknown"]
        .iter()
        .map(|k| c[k].as_u64().unwrap())
        .sum();
    // A 16 m grid holds 40 x 40 cells per frame; most have points and ground truth.
    assert!(cells > 3000 && cells <= 3 * 1600, "{cells}");
}

/// Every command that reads a configuration prints all of it in its `--json`
/// summary, and times in milliseconds.
#[test]
fn json_summaries_carry_the_whole_configuration() {
    let Some(seq) = sample() else { return };
    let dir = tempfile::tempdir().unwrap();
    let at = |name: &str| arg(&dir.path().join(name)).to_string();
    let (picture, map, poses, adapted) = (at("f.png"), at("m.png"), at("p.txt"), at("a.json"));
    for args in [
        vec!["render", &seq, "--frame", "2", "-o", &picture],
        vec!["map", &seq, "-o", &map],
        vec!["odometry", &seq, "-o", &poses],
        vec!["adapt", &seq, "-o", &adapted],
    ] {
        let summary = crate::common::json_summary(&args);
        let config = &summary["config"];
        assert!(
            config["grid"]["size_m"].is_number() && config["adapt"].is_object(),
            "{args:?}: {config}"
        );
        assert!(summary.get("seconds").is_none(), "{args:?}");
    }
    let summary = crate::common::json_summary(&["adapt", &seq, "-o", &adapted]);
    assert!(summary["elapsed_ms"].as_f64().unwrap() > 0.0);
}

#[test]
fn run_emits_one_grid_per_frame() {
    let Some(seq) = sample() else { return };
    let out = success(travmap(&["run", &seq, "--frames", "3..6", "--json"]));
    let (lines, summary) = crate::common::json_records(&out);
    assert_eq!(lines.len(), 3, "three frames");
    assert!(summary["config"].is_object() && summary["model"].is_object());
    assert_eq!(summary["frames"], 3);
    assert!(summary["timings"]["latency_ms"]["median"].as_f64().unwrap() > 0.0);
    for (line, frame) in lines.iter().zip(3..) {
        assert_eq!(line["frame"], frame);
        let cells = line["cells"].as_array().unwrap();
        assert_eq!(cells.len(), 900);
        assert!(
            cells
                .iter()
                .all(|c| [-1, 0, 100].contains(&c.as_i64().unwrap()))
        );
        let traversable = cells.iter().filter(|c| c.as_i64() == Some(0)).count();
        assert!(
            traversable > 200,
            "frame {frame}: {traversable} traversable cells on a street"
        );
        // The LiDAR sees nothing within ~2.5 m of itself; the road 4.8 m ahead is free.
        assert_eq!(cells[15 * 30 + 15], -1, "frame {frame}");
        assert_eq!(cells[15 * 30 + 27], 0, "frame {frame}");
    }
    let text = success(travmap(&["run", &seq, "--frames", "2", "--ascii"]));
    assert_eq!(
        text.lines().filter(|l| l.starts_with("  |")).count(),
        30,
        "{text}"
    );
}

#[test]
fn train_writes_a_model_that_eval_uses() {
    let Some(seq) = sample() else { return };
    let dir = tempfile::tempdir().unwrap();
    let model = dir.path().join("m.json");
    let model = arg(&model);
    let doc = json_summary(&quick(&["train", &seq, "--frames", "0..2", "-o", model]));
    assert_eq!(doc["c"], 10.0);
    assert!(doc["support_vectors"].as_u64().unwrap() > 10);
    assert!(doc["samples"].as_u64().unwrap() > 5000);
    let file: Value = serde_json::from_slice(&std::fs::read(model).unwrap()).unwrap();
    assert_eq!(file["format"], "travmap-svm");
    assert_eq!(file["version"], 1);
    let out = success(travmap(&["eval", &seq, "--model", model, "--frames", "2"]));
    assert_contains(&out, &["over 1 frame\n", "m.json"]);
    // No temporary file is left beside the model.
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1);
}

#[test]
fn embedded_models_are_what_the_documented_command_trains() {
    let Some(seq) = sample() else { return };
    if seq != "../shared/data/semantickitti-00/sequences/00"
        && !seq.ends_with("/../shared/data/semantickitti-00/sequences/00")
    {
        eprintln!("skipping: unexpected sample path {seq}");
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    // The retraining script docs/method.md gives, on this binary.
    let trained = std::process::Command::new("scripts/train_embedded_model.sh")
        .arg(dir.path())
        .env("TRAVMAP", env!("CARGO_BIN_EXE_travmap"))
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .output()
        .unwrap();
    assert!(
        trained.status.success(),
        "{}",
        String::from_utf8_lossy(&trained.stderr)
    );
    // Every part's record of its training seconds, however deep (the fallback has a
    // hybrid part of its own), is the one thing that differs between two runs.
    fn strip_seconds(v: &mut Value) {
        if let Some(object) = v.as_object_mut() {
            if let Some(training) = object.get_mut("training").and_then(Value::as_object_mut) {
                training.remove("seconds");
            }
            object.values_mut().for_each(strip_seconds);
        }
    }
    let strip_time = |bytes: &[u8]| {
        let mut v: Value = serde_json::from_slice(bytes).unwrap();
        strip_seconds(&mut v);
        v
    };
    for file in ["road_model.json", "offroad_model.json"] {
        let shipped = std::fs::read(format!("crates/method/src/classifier/{file}")).unwrap();
        assert!(
            strip_time(&std::fs::read(dir.path().join(file)).unwrap()) == strip_time(&shipped),
            "crates/method/src/classifier/{file} is stale: retrain it with scripts/train_embedded_model.sh"
        );
    }
}

#[test]
fn crossval_reports_held_out_scores() {
    let Some(seq) = sample() else { return };
    let doc = json_summary(&quick(&["crossval", &seq, "--set", "training.folds=3"]));
    assert_eq!(doc["scored_frames"], 3);
    assert_eq!(doc["folds"].as_array().unwrap().len(), 3);
    let accuracy = doc["scores"]["accuracy"].as_f64().unwrap();
    assert!(accuracy > 0.85, "{accuracy}");
}

#[test]
fn config_prints_the_effective_settings_and_rejects_unknown_keys() {
    let doc = json_summary(&["config", "--set", "grid.size_m=24"]);
    assert_eq!(doc["config"]["grid"]["size_m"], 24.0);
    assert_eq!(doc["config"]["features"]["curvity_bins"], 160);
    let toml = success(travmap(&["config"]));
    assert_contains(&toml, &["[grid]", "cell_size_m = 0.4"]);
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("c.toml");
    std::fs::write(
        &file,
        toml.replace("curvity_bins = 160", "curvity_bins = 80"),
    )
    .unwrap();
    let doc = json_summary(&["config", "--config", arg(&file)]);
    assert_eq!(doc["config"]["features"]["curvity_bins"], 80);
    let err = crate::common::usage_error(travmap(&["config", "--set", "grid.bogus=1"]));
    assert_contains(&err, &["no field `bogus`"]);
    // A value out of range is a mistake in the command line too (exit 2).
    let err = crate::common::usage_error(travmap(&["config", "--set", "grid.size_m=-3"]));
    assert_contains(&err, &["grid.size_m must be > 0"]);
}

#[test]
fn a_model_trained_for_other_features_is_refused() {
    let Some(seq) = sample() else { return };
    let err = clean_failure(travmap(&[
        "eval",
        &seq,
        "--set",
        "features.curvity_bins=80",
    ]));
    assert_contains(
        &err,
        &[
            "embedded road model was trained with features.curvity_bins = 160",
            "--set features.curvity_bins=160",
        ],
    );
}

#[test]
fn bench_prints_every_stage_and_throughput() {
    let Some(seq) = sample() else { return };
    let out = success(travmap(&["bench", &seq, "--repeats", "2"]));
    for stage in [
        "read",
        "integrate",
        "grid",
        "geometric features",
        "classify",
        "filter",
        "latency",
        "appearance",
        "write",
        "floor",
        "frames/s",
    ] {
        assert!(out.contains(stage), "missing {stage}:\n{out}");
    }
    let doc = json_summary(&["bench", &seq, "--repeats", "2"]);
    assert_eq!(doc["timed_frames"], 4);
    assert!(doc["timings"]["latency_ms"]["median"].as_f64().unwrap() > 0.0);
    // The ratio of two medians timed in this run: only its presence is checked here,
    // since the other tests share the machine (speed figures live in `bench`).
    assert!(doc["floor_ms"]["median"].as_f64().unwrap() > 0.0);
    assert!(doc["latency_over_floor"].as_f64().unwrap() > 0.0);
    assert!(doc["one_thread"]["frames_per_second"].as_f64().unwrap() > 0.0);
}

#[test]
fn bench_tools_times_every_subcommand_as_a_child_process() {
    let Some(seq) = sample() else { return };
    let args = [
        "bench",
        &seq,
        "--repeats",
        "1",
        "--tools",
        "--tool-repeats",
        "1",
    ];
    let doc = json_summary(&args);
    let rows = doc["tools"].as_array().unwrap();
    // KITTI input: convert, then annotate of the input and of convert's MCAP.
    let kinds: Vec<String> = rows
        .iter()
        .map(|row| format!("{} {} {}", row["tool"], row["input"], row["passthrough"]))
        .collect();
    let expected = [
        r#""convert" "kitti" null"#,
        r#""annotate" "kitti" true"#,
        r#""annotate" "kitti" false"#,
        r#""annotate" "mcap" true"#,
        r#""annotate" "mcap" false"#,
        r#""dataset" "kitti" null"#,
        r#""adapt" "kitti" null"#,
    ];
    assert_eq!(kinds, expected, "{doc}");
    for row in rows {
        assert_eq!(row["frames"], 6, "{row}");
        // Six scans about 0.1 s apart (times.txt: 0.0 to 0.518 s) span 0.62 s.
        let recorded_ms = row["recorded_ms"].as_f64().unwrap();
        assert!((recorded_ms - 620.0).abs() < 10.0, "{row}");
        assert!(row.get("skipped").is_none(), "{row}");
        for (timing, threads) in [(&row["one_thread"], Some(1)), (&row["all_cores"], None)] {
            let rate = |key: &str| timing[key].as_f64().unwrap();
            assert!(rate("frames_per_second") > 0.0, "{row}");
            assert!(rate("megabytes_per_second") > 0.0, "{row}");
            let recorded_s_per_wall_s = recorded_ms / rate("wall_ms");
            assert!(
                (rate("recorded_s_per_wall_s") - recorded_s_per_wall_s).abs()
                    < 1e-9 * recorded_s_per_wall_s,
                "{row}"
            );
            if let Some(threads) = threads {
                assert_eq!(timing["threads"], threads, "{row}");
            }
            if cfg!(target_os = "linux") {
                assert!(rate("peak_rss_mib") > 0.0, "{row}");
            }
            // The roofline: the method alone (no method in convert) and the disk.
            let synced = row["synced_write_ms"].as_f64().unwrap();
            let roofline = match row["tool"].as_str() {
                Some("convert") => {
                    assert!(timing["method_ms"].is_null(), "{row}");
                    synced
                }
                _ => rate("method_ms").max(synced),
            };
            let ratio = rate("wall_ms") / roofline;
            assert!(
                (rate("roofline_ratio") - ratio).abs() < 1e-9 * ratio,
                "{row}"
            );
        }
    }
}

#[test]
fn render_draws_truth_prediction_and_errors_cell_by_cell() {
    use travmap_method::grid::CellClass;
    use travmap_outputs::figure::panel_origin;
    use travmap_outputs::palette::Palette;
    use travmap_outputs::rendering::cell_origin_px;
    let Some(seq) = sample() else { return };
    let dir = tempfile::tempdir().unwrap();
    let picture = dir.path().join("frame.png");
    write_output("render", &seq, &picture, &["--frame", "2"]);
    let image = crate::common::read_png(&picture);
    // 30 cells of 16 pixels: panels 480 wide, side by side with their titles,
    // scale bar and legend around them.
    let (last_x, top) = panel_origin(2, 480);
    assert!(
        image.width >= last_x + 480 && image.height > top + 480,
        "{} x {}",
        image.width,
        image.height
    );

    // The same frame through the library: every cell's colour in every panel.
    let config = travmap_core::Config::default();
    let model =
        travmap_method::classifier::SvmModel::embedded(travmap_core::config::LabelRule::Road)
            .unwrap();
    let source = travmap_io::Source::open(Path::new(&seq), &Default::default(), &|_| {}).unwrap();
    let selection = travmap_run::DriveRun::new(source, 2..3);
    let mut result = None;
    selection
        .run::<travmap_core::Error>(&config, Some(&model), |r| {
            result = Some(r);
            Ok(())
        })
        .unwrap();
    let result = result.unwrap();
    let (truth, predicted) = (result.ground_truth.unwrap(), result.filtered.unwrap());
    let palette = Palette::SAFE;
    let pixel = |x: u32, y: u32| {
        let at = 3 * (y * image.width + x) as usize;
        [image.rgb[at], image.rgb[at + 1], image.rgb[at + 2]]
    };
    // The sensor's marker covers the cells around it.
    let [min_x, min_y] = result.layout.min_corner_in_world();
    let sensor = result
        .layout
        .cell_of_local(
            result.sensor_in_world[0] - min_x,
            result.sensor_in_world[1] - min_y,
        )
        .unwrap();
    let (sensor_col, sensor_row) = result.layout.col_row(sensor);
    let (mut false_positives, mut false_negatives) = (0, 0);
    for cell in 0..900 {
        let (col, row) = result.layout.col_row(cell);
        if col.abs_diff(sensor_col) <= 1 && row.abs_diff(sensor_row) <= 1 {
            continue;
        }
        let (x, y) = cell_origin_px(col, row, 30, 16);
        let at = |panel: usize| {
            let (px, py) = panel_origin(panel, 480);
            pixel(px + x + 8, py + y + 8)
        };
        assert_eq!(at(0), palette.class(truth[cell]), "truth, cell {cell}");
        assert_eq!(
            at(1),
            palette.class(predicted[cell]),
            "prediction, cell {cell}"
        );
        let error = at(2);
        assert_eq!(
            error,
            palette.error(predicted[cell], truth[cell]),
            "errors, cell {cell}"
        );
        match (predicted[cell], truth[cell]) {
            (CellClass::Traversable, CellClass::NonTraversable) => false_positives += 1,
            (CellClass::NonTraversable, CellClass::Traversable) => false_negatives += 1,
            _ => {}
        }
    }
    assert!(
        false_positives + false_negatives > 0,
        "the picture shows some errors"
    );
    // --all writes one picture per frame.
    let all = dir.path().join("all");
    write_output("render", &seq, &all, &["--all", "--frames", "0..3"]);
    assert_eq!(std::fs::read_dir(&all).unwrap().count(), 3);
    crate::common::usage_error(travmap(&["render", &seq, "-o", arg(&all)]));
    // Into the folder again, and not into a folder whose parent is missing: no
    // command makes the folders above its output.
    write_output("render", &seq, &all, &["--all", "--frames", "0..1"]);
    let deep = dir.path().join("missing").join("all");
    let out = travmap(&[
        "render",
        &seq,
        "--all",
        "--frames",
        "0..1",
        "-o",
        arg(&deep),
    ]);
    let err = clean_failure(out);
    assert_contains(&err, &["missing", "does not exist"]);
    assert!(!dir.path().join("missing").exists());
}

#[test]
fn suspicious_arguments_are_refused_or_warned_about() {
    let Some(seq) = sample() else { return };
    let dir = tempfile::tempdir().unwrap();
    // The same input twice, however spelled, would count its frames twice.
    let again = format!("{seq}/../00");
    let err = clean_failure(travmap(&["eval", &seq, &again]));
    assert_contains(&err, &["are the same input"]);
    // convert copies a log whole: --frames is for KITTI input.
    let drive = dir.path().join("d.mcap");
    write_output("convert", &seq, &drive, &["--frames", "0..2"]);
    // A hard link is the same file under another name.
    let linked = dir.path().join("linked.mcap");
    std::fs::hard_link(&drive, &linked).unwrap();
    let err = clean_failure(travmap(&["eval", arg(&drive), arg(&linked)]));
    assert_contains(&err, &["are the same input"]);
    let other = dir.path().join("e.mcap");
    let err = clean_failure(travmap(&[
        "convert",
        arg(&drive),
        "-o",
        arg(&other),
        "--frames",
        "0..1",
    ]));
    assert_contains(
        &err,
        &["--frames applies to KITTI input; a log is converted whole"],
    );
    // Unbounded or empty repeats, and --frame with --frames, are usage errors.
    for args in [
        vec!["bench", &seq, "--repeats", "0"],
        vec!["bench", &seq, "--repeats", "4000000000"],
        vec!["bench", &seq, "--tools", "--tool-repeats", "0"],
        vec!["bench", &seq, "--tool-repeats", "2"],
        vec![
            "render", &seq, "--frame", "1", "--frames", "0..2", "-o", "x.png",
        ],
    ] {
        let err = crate::common::usage_error(travmap(&args));
        assert!(err.contains("repeats") || err.contains("--frames"), "{err}");
    }
    // MCAP-only flags on a KITTI directory are said to be ignored.
    let out = travmap(&["eval", &seq, "--frames", "0..3", "--cloud-topic", "/points"]);
    assert!(out.status.success());
    let err = crate::common::stderr(&out);
    assert_contains(&err, &["warning: --cloud-topic applies to recorded logs"]);
    // So are a log's pose source and a rate where times.txt gives the stamps.
    let out = travmap(&[
        "run", &seq, "--frames", "0..1", "--poses", "tf", "--rate", "5",
    ]);
    assert!(out.status.success());
    let err = crate::common::stderr(&out);
    assert_contains(
        &err,
        &[
            "warning: --poses tf names a recorded log's poses",
            "whose poses.txt is used",
            "times.txt gives the scans' stamps: --rate 5 is not used",
        ],
    );
}

#[test]
fn eval_of_frames_without_labels_is_an_error_that_names_where_they_were_looked_for() {
    let Some(seq) = sample() else { return };
    // Frames 3-5 of the sample have no labels.
    let err = crate::common::clean_failure(travmap(&["eval", &seq, "--frames", "3..6"]));
    assert_contains(
        &err,
        &[
            "no frame of the input has labels",
            "labels/NNNNNN.label",
            "`travmap run` classifies frames without labels",
        ],
    );
    let out = travmap(&["eval", &seq, "--frames", "3..6", "--json"]);
    assert_eq!(out.status.code(), Some(1));
    assert!(out.stdout.is_empty(), "no summary: nothing was scored");
    let error: Value = serde_json::from_str(crate::common::stderr(&out).trim()).unwrap();
    assert_eq!(error["exit_code"], 1);
    // A drive as MCAP says where a log's labels are read from.
    let dir = tempfile::tempdir().unwrap();
    let drive = dir.path().join("d.mcap");
    success(travmap(&[
        "convert",
        &seq,
        "--frames",
        "3..6",
        "-o",
        arg(&drive),
    ]));
    let err = crate::common::clean_failure(travmap(&["eval", arg(&drive)]));
    assert_contains(&err, &["d.mcap: a `label` field of its point clouds"]);
}

#[test]
fn eval_tells_training_scans_from_unseen_ones_by_content() {
    let Some(seq) = sample() else { return };
    let Some(other) = crate::common::shared_data("semantickitti-07-000964/sequences/07") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    // The embedded model learnt from the shipped frames 0-2: an MCAP copy is the same scans.
    let (_, drive) = crate::common::sample_as_mcap(dir.path(), &[]).unwrap();
    let out = success(travmap(&["eval", arg(&drive)]));
    assert_contains(
        &out,
        &["every scored frame is a scan this model was trained on"],
    );
    // A model of frames 0-1 on frames 0-2, and on another street.
    let model = dir.path().join("m.json");
    write_output(
        "train",
        Path::new(&seq),
        &model,
        &quick(&["--frames", "0..2"]),
    );
    let out = success(travmap(&[
        "eval",
        &seq,
        "--frames",
        "0..3",
        "--model",
        arg(&model),
    ]));
    assert_contains(
        &out,
        &["2 of the 3 scored frames are scans this model was trained on"],
    );
    let out = success(travmap(&["eval", arg(&other), "--model", arg(&model)]));
    assert_contains(
        &out,
        &["none of the scored frames is a scan this model was trained on"],
    );
    let doc = json_summary(&["eval", arg(&other), "--model", arg(&model)]);
    assert_eq!(doc["training_frames_scored"], 0);
}

#[test]
fn crossval_over_several_inputs_holds_out_each_in_turn() {
    let Some(seq) = sample() else { return };
    let Some(other) = crate::common::shared_data("semantickitti-07-000964/sequences/07") else {
        return;
    };
    let doc = json_summary(&quick(&["crossval", &seq, arg(&other)]));
    let held_out = doc["held_out"].as_array().unwrap();
    assert_eq!(held_out.len(), 2);
    // Seq 00 has three labelled frames, seq 07 one; each scored by the other's model.
    assert_eq!(held_out[0]["scored_frames"], 3);
    assert_eq!(held_out[1]["scored_frames"], 1);
    assert_eq!(doc["scored_frames"], 4);
    let miou = doc["scores"]["miou"].as_f64().unwrap();
    assert!(miou > 0.75, "pooled held-out mIoU {miou}");
}

/// What a terminal shows of `raw` (a pseudo-terminal's bytes): each line as the
/// text after its last carriage return, escape sequences left out.
fn visible_lines(raw: &str) -> Vec<String> {
    raw.split('\n')
        .map(|line| {
            let shown = line
                .rsplit('\r')
                .find(|part| !part.trim().is_empty())
                .unwrap_or("");
            let mut text = String::new();
            let mut chars = shown.chars();
            while let Some(c) = chars.next() {
                if c == '\u{1b}' {
                    // CSI: ESC [ parameters, then one final letter.
                    chars.by_ref().find(|c| c.is_ascii_alphabetic());
                } else {
                    text.push(c);
                }
            }
            text
        })
        .collect()
}

#[test]
fn progress_bars_never_share_a_line_with_results_in_a_terminal() {
    let Some(seq) = sample() else { return };
    let binary = env!("CARGO_BIN_EXE_travmap");
    for (command, bar) in [("eval", "evaluating"), ("run", "predicting")] {
        // `script` runs the command in a pseudo-terminal of 40 rows x 100 columns.
        let shell = format!("stty rows 40 cols 100; {binary} {command} {seq}");
        let out = match std::process::Command::new("script")
            .args(["-qec", &shell, "/dev/null"])
            .current_dir(env!("CARGO_MANIFEST_DIR"))
            .output()
        {
            Ok(out) => out,
            Err(_) => {
                crate::common::skip::<()>("`script` (util-linux) is not installed");
                return;
            }
        };
        let raw = String::from_utf8_lossy(&out.stdout);
        assert!(out.status.success(), "{command} in a terminal:\n{raw}");
        assert!(raw.contains(bar), "{command} drew no progress bar:\n{raw}");
        let lines = visible_lines(&raw);
        assert!(
            lines.iter().all(|line| !line.contains(bar)),
            "{command}: a bar is left on screen, or shares a line with a result:\n{lines:#?}"
        );
        assert!(
            lines
                .iter()
                .any(|line| line.contains("travmap (filtered)") || line.contains("median latency"))
        );
    }
}

#[test]
fn set_takes_bare_text_and_every_configuration_mistake_is_a_usage_error() {
    let out = success(travmap(&["config", "--set", "integration.poses=tf", "-q"]));
    assert!(out.contains("poses = \"tf\""), "{out}");
    for (assignment, named) in [
        ("grid.size_m=-5", "grid.size_m must be > 0"),
        ("integration.poses=bogus", "`auto`, `tf`"),
        (
            "grid.size_m=abc",
            "`grid.size_m`: `abc` is not a number (e.g. grid.size_m=12.0)",
        ),
        ("integration.scans=x", "`x` is not a whole number"),
        ("filter.enabled=yes", "`yes` is not true or false"),
        (
            "ground_truth.label_map=/no/such/map.toml",
            "/no/such/map.toml",
        ),
    ] {
        let err = crate::common::usage_error(travmap(&["config", "--set", assignment]));
        assert!(err.contains(named), "--set {assignment}: {err}");
        // A number wants no quoting: TOML's hint about strings would mislead.
        assert!(!err.contains("must be quoted"), "--set {assignment}: {err}");
    }
    // A range as other tools write it is said in this tool's words.
    let err = crate::common::usage_error(travmap(&["run", "/nonexistent", "--frames", "0-2"]));
    assert_contains(&err, &["`0..3` or `0..=2`"]);
}

#[test]
fn quiet_keeps_the_answer_and_drops_the_chatter() {
    let Some(seq) = sample() else { return };
    let scores = success(travmap(&["eval", &seq, "-q"]));
    assert!(scores.contains("travmap (filtered)"), "{scores}");
    assert!(
        !scores.contains("inputs:") && !scores.contains("model:"),
        "{scores}"
    );
    let rows = success(travmap(&["run", &seq, "-q", "--frames", "2..4"]));
    assert_eq!(rows.lines().count(), 3, "a header and two rows:\n{rows}");
}

#[test]
fn settings_that_would_never_end_or_exhaust_memory_are_refused() {
    for (assignment, named) in [
        (
            "registration.max_points_per_voxel=4294967295",
            "max_points_per_voxel in 1..=10000",
        ),
        (
            "training.c_values=[1e300]",
            "training.c_values must be in (0.0, 1000000.0], got 1e300",
        ),
        ("training.tolerance=1e-300", "training.tolerance must be in"),
        ("adapt.rounds=1000000", "adapt.rounds must be at most 20"),
        ("adapt.c=1e300", "adapt.c must be in"),
    ] {
        let err = crate::common::usage_error(travmap(&["config", "--set", assignment]));
        assert!(err.contains(named), "--set {assignment}: {err}");
    }
}

/// Each command's --help: its own options first, the shared ones under headings,
/// examples at the end; -h leaves the examples out.
#[test]
fn help_puts_the_commands_own_options_first_and_ends_with_examples() {
    for command in [
        "run", "eval", "annotate", "convert", "map", "render", "train", "dataset", "adapt",
        "crossval", "odometry", "bench", "config",
    ] {
        let long = success(travmap(&[command, "--help"]));
        let short = success(travmap(&[command, "-h"]));
        assert!(
            long.contains("\nExamples (SEQ: a KITTI sequence folder"),
            "{command}:\n{long}"
        );
        assert!(!short.contains("\nExamples"), "{command} -h:\n{short}");
        let at = |heading: &str| long.find(&format!("\n{heading}:\n"));
        let options = at("Options").unwrap_or_else(|| panic!("{command}:\n{long}"));
        for shared in [
            "Reading the inputs",
            "Recorded logs and packets",
            "Configuration",
            "Reporting",
        ] {
            assert!(
                at(shared).is_none_or(|heading| heading > options),
                "{command}: {shared}"
            );
        }
    }
}

/// `travmap --help` lists each command on one line of a wide terminal; the details
/// follow in the command's own help.
#[test]
fn every_command_is_summed_up_in_one_short_line() {
    let help = success(travmap(&["--help"]));
    let commands = &help[help.find("Commands:\n").unwrap()..help.find("\nOptions:").unwrap()];
    for line in commands.lines().skip(1) {
        assert!(line.chars().count() <= 120, "{line}");
    }
    let adapt = success(travmap(&["adapt", "-h"]));
    assert!(!adapt.contains("never read"), "{adapt}");
    let bench = success(travmap(&["bench", "--help"]));
    assert!(
        bench.contains("(convert, annotate, dataset, adapt)"),
        "{bench}"
    );
}

/// Shell completions and man pages come from the command line's own definition.
#[test]
fn completions_and_man_pages_are_generated() {
    for shell in ["bash", "zsh", "fish", "elvish", "powershell"] {
        let script = success(travmap(&["completions", shell]));
        assert!(
            script.contains("annotate") && script.contains("lidar-calibration"),
            "{shell}"
        );
    }
    let dir = tempfile::tempdir().unwrap();
    success(travmap(&["man", "-o", arg(dir.path())]));
    let page = std::fs::read_to_string(dir.path().join("travmap-annotate.1")).unwrap();
    assert!(
        page.contains(".TH TRAVMAP-ANNOTATE 1") && page.contains("travmap\\-annotate"),
        "{page}"
    );
    // The synopsis is the command as typed.
    let synopsis = &page[page.find(".SH SYNOPSIS").unwrap()..];
    assert!(synopsis.contains("\\fBtravmap annotate\\fR"), "{synopsis}");
    assert_eq!(
        std::fs::read_dir(dir.path()).unwrap().count(),
        17,
        "travmap.1 and one per command"
    );
}

/// What is read or written otherwise than asked is said: a frame range cut at the
/// input's end, an output whose extension names another format.
#[test]
fn a_cut_frame_range_and_an_odd_extension_are_said() {
    let Some(seq) = sample() else { return };
    let out = travmap(&["run", &seq, "--frames", "4..10", "-q"]);
    assert!(out.status.success());
    assert_contains(
        &crate::common::stderr(&out),
        &["frames 4..=9 goes past its last frame, 5: reading 4..=5"],
    );
    let dir = tempfile::tempdir().unwrap();
    let text = dir.path().join("x.txt");
    let out = travmap(&["convert", &seq, "-o", arg(&text), "-q", "--frames", "0..2"]);
    assert!(out.status.success());
    assert_contains(
        &crate::common::stderr(&out),
        &["is written as an MCAP file"],
    );
}

#[test]
fn what_the_surveys_find_given_back_maps_the_same_unsurveyed() {
    let Some(scene) = crate::common::shared_data("nuscenes-lidarseg-scene-1072") else {
        return;
    };
    let cells = |stdout: &str| -> Vec<Value> {
        let (frames, _) = crate::common::json_records(stdout);
        frames.into_iter().map(|f| f["cells"].clone()).collect()
    };
    let surveyed = travmap(&["run", arg(&scene), "--json"]);
    let said = crate::common::stderr(&surveyed);
    let setting = said
        .split("--set '")
        .nth(1)
        .and_then(|rest| rest.split('\'').next())
        .unwrap_or_else(|| panic!("the notice gives the box as a setting: {said}"));
    assert!(
        setting.starts_with("vehicle.own_points_box_m=["),
        "{setting}"
    );
    // And the poses' refinement the other survey decided (nuScenes' 2-D poses).
    let refine = "integration.refine_poses=always";
    assert_contains(&said, &[&format!("--set {refine})")]);
    let given = travmap(&[
        "run",
        arg(&scene),
        "--json",
        "--set",
        setting,
        "--set",
        refine,
    ]);
    let unsaid = crate::common::stderr(&given);
    assert!(!unsaid.contains("own points found"), "{unsaid}");
    assert!(!unsaid.contains("lay the ground"), "{unsaid}");
    assert_eq!(cells(&success(given)), cells(&success(surveyed)));
}
