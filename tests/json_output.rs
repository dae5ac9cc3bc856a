//! One JSON convention for every command: JSON Lines on stdout (`frame` records,
//! then one `summary`), an `error` object on stderr; each command's output checked
//! against its schema in `schemas/json/` by Python's jsonschema.

use std::path::Path;

use crate::common::{arg, travmap, with_settings};

/// Runs travmap with `args` (which include `--json`), validates what it printed
/// against `command`'s schema, and returns its exit code.
fn validate(command: &str, args: &[&str]) -> i32 {
    let python = crate::common::env_var("TRAVMAP_CLIENT_PYTHON", "a Python with jsonschema")
        .expect("checked by the caller");
    let out = travmap(args);
    let dir = tempfile::tempdir().unwrap();
    let (stdout, stderr) = (dir.path().join("stdout"), dir.path().join("stderr"));
    std::fs::write(&stdout, &out.stdout).unwrap();
    std::fs::write(&stderr, &out.stderr).unwrap();
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let checked = std::process::Command::new(python)
        .arg(root.join("tests/clients/validate_json.py"))
        .arg(root.join("schemas/json"))
        .args([command, arg(&stdout), arg(&stderr)])
        .output()
        .unwrap();
    assert!(
        checked.status.success(),
        "{args:?}: {}\nstdout: {}\nstderr: {}",
        String::from_utf8_lossy(&checked.stderr),
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr),
    );
    let count: serde_json::Value = serde_json::from_slice(&checked.stdout).unwrap();
    assert!(
        count["checked"].as_u64().unwrap() > 0,
        "{args:?}: nothing printed"
    );
    out.status.code().unwrap()
}

#[test]
#[ignore = "needs the real clients: source .ci/clients.sh, then cargo test --release -- --ignored"]
fn every_command_prints_json_that_matches_its_schema() {
    let Some(seq) = crate::common::sample() else {
        return;
    };
    if crate::common::env_var("TRAVMAP_CLIENT_PYTHON", "a Python with jsonschema").is_none() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let seq = arg(&seq);
    let out = |name: &str| arg(&dir.path().join(name)).to_string();
    let (drive, model, cells) = (out("d.mcap"), out("m.json"), out("c.parquet"));
    let (annotated, picture, converted) = (out("a.mcap"), out("f.png"), out("c.mcap"));
    let trajectory = out("poses.txt");
    let adapted = out("adapted.json");
    let (labels, taught) = (out("labels.parquet"), out("taught.json"));
    let (map_picture, map_cells, nav2) = (out("map.png"), out("map.parquet"), out("site.yaml"));
    let quick = ["training.c_values=[10]", "training.gamma_values=[0.05]"];
    let quick_crossval = [&quick[..], &["training.folds=3"]].concat();
    let runs: Vec<(&str, Vec<&str>)> = vec![
        (
            "convert",
            vec!["convert", seq, "--frames", "0..4", "-o", &drive],
        ),
        // A recorded log converted: the other shape of the summary.
        ("convert", vec!["convert", &drive, "-o", &converted]),
        ("run", vec!["run", seq, "--frames", "2..4"]),
        ("run", vec!["run", &drive]),
        ("eval", vec!["eval", seq, "--frames", "0..3"]),
        (
            "train",
            with_settings(&["train", seq, "--frames", "0..3", "-o", &model], &quick),
        ),
        (
            "crossval",
            with_settings(&["crossval", seq, "--frames", "0..3"], &quick_crossval),
        ),
        ("dataset", vec!["dataset", &drive, "-o", &cells]),
        (
            "label",
            vec![
                "label",
                seq,
                "-o",
                &labels,
                "--ask",
                "20",
                "--answers-from-ground-truth",
            ],
        ),
        (
            "train",
            vec!["train", &labels, "--prior", "road", "-o", &taught],
        ),
        ("adapt", vec!["adapt", seq, "-o", &adapted]),
        ("annotate", vec!["annotate", &drive, "-o", &annotated]),
        (
            "render",
            vec!["render", seq, "--frame", "2", "-o", &picture],
        ),
        (
            "bench",
            vec!["bench", seq, "--frames", "0..4", "--repeats", "1"],
        ),
        (
            "bench",
            vec![
                "bench",
                seq,
                "--frames",
                "0..4",
                "--repeats",
                "1",
                "--tools",
                "--tool-repeats",
                "1",
            ],
        ),
        // A recorded log: the convert and MCAP rows are skipped, with a reason.
        (
            "bench",
            vec![
                "bench",
                &drive,
                "--repeats",
                "1",
                "--tools",
                "--tool-repeats",
                "1",
            ],
        ),
        (
            "map",
            vec![
                "map",
                seq,
                "-o",
                &map_picture,
                "--cells",
                &map_cells,
                "--nav2",
                &nav2,
            ],
        ),
        (
            "odometry",
            vec!["odometry", seq, "--frames", "0..3", "-o", &trajectory],
        ),
        ("config", vec!["config"]),
    ];
    for (command, mut args) in runs {
        args.push("--json");
        assert_eq!(validate(command, &args), 0, "{args:?}");
    }
    // Errors: a missing input (exit 1, naming it) and a malformed flag (exit 2).
    assert_eq!(validate("eval", &["eval", "/no/such/input", "--json"]), 1);
    assert_eq!(
        validate("eval", &["eval", seq, "--frames", "x", "--json"]),
        2
    );
}

#[test]
fn skipped_frames_are_listed_in_the_summary() {
    let Some(seq) = crate::common::sample() else {
        return;
    };
    // Frame 1's scan is cut short: with --keep-going it is skipped, exit 3.
    let dir = tempfile::tempdir().unwrap();
    let copy = dir.path().join("seq");
    std::fs::create_dir_all(copy.join("velodyne")).unwrap();
    for name in ["calib.txt", "poses.txt", "times.txt"] {
        std::fs::copy(seq.join(name), copy.join(name)).unwrap();
    }
    for i in 0..3 {
        let name = format!("velodyne/{i:06}.bin");
        std::fs::copy(seq.join(&name), copy.join(&name)).unwrap();
    }
    std::fs::write(copy.join("velodyne/000001.bin"), [0u8; 20]).unwrap();
    let out = travmap(&["run", arg(&copy), "--json", "--keep-going"]);
    assert_eq!(out.status.code(), Some(3));
    let (frames, summary) = crate::common::json_records(&crate::common::stdout(&out));
    assert_eq!(frames.len(), 2);
    let skipped = summary["skipped"].as_array().unwrap();
    assert_eq!(skipped.len(), 1, "{summary}");
    assert_eq!(skipped[0]["frame"], 1);
    assert!(
        skipped[0]["reason"]
            .as_str()
            .unwrap()
            .contains("not a multiple of 16")
    );
}

/// A path that is not UTF-8 (a Linux file name may hold any byte but / and NUL) is
/// written with U+FFFD in JSON, never a panic: in a summary after the outputs are
/// committed, in an error record.
#[test]
fn paths_that_are_not_utf8_are_written_lossily() {
    use std::ffi::OsStr;
    use std::os::unix::ffi::OsStrExt;
    let Some(sample) = crate::common::sample() else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let odd = dir.path().join(OsStr::from_bytes(b"bad\xff"));
    std::fs::create_dir(&odd).unwrap();
    let run = |args: &[&OsStr]| {
        std::process::Command::new(env!("CARGO_BIN_EXE_travmap"))
            .args(args)
            .arg("--json")
            .output()
            .unwrap()
    };
    let (map, nav2, cells) = (odd.join("m.png"), odd.join("m.yaml"), odd.join("c.parquet"));
    let out = run(&[
        "map".as_ref(),
        sample.as_os_str(),
        "-o".as_ref(),
        map.as_os_str(),
        "--nav2".as_ref(),
        nav2.as_os_str(),
        "--cells".as_ref(),
        cells.as_os_str(),
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let summary: serde_json::Value = serde_json::from_slice(
        out.stdout
            .split(|&b| b == b'\n')
            .rfind(|l| !l.is_empty())
            .unwrap(),
    )
    .unwrap();
    assert!(
        summary["output"]
            .as_str()
            .unwrap()
            .ends_with("bad\u{fffd}/m.png")
    );
    assert!(
        summary["nav2"]["yaml"]
            .as_str()
            .unwrap()
            .ends_with("bad\u{fffd}/m.yaml")
    );

    let missing = odd.join("no-such-drive");
    let out = run(&["eval".as_ref(), missing.as_os_str()]);
    assert_eq!(
        out.status.code(),
        Some(1),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let error: serde_json::Value = serde_json::from_slice(&out.stderr).unwrap();
    assert_eq!(error["type"], "error");
}
