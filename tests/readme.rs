//! The docs' figures come from the commands they quote. Each test runs a quoted
//! command and checks that the README or a page of `docs/` shows what it drew (the
//! pictures, byte for byte) or printed (the score rows of docs/method.md's
//! "Evaluation on the shipped data, honestly"). `TRAVMAP_BLESS=1 cargo test --release
//! --test integration readme::` redraws the pictures; a score that moved fails with
//! the row the docs should now show.

use std::path::Path;

use crate::common::{arg, success, travmap};
use serde_json::Value;

/// The README and every page of `docs/`, one after the other.
fn readme() -> String {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut pages: Vec<_> = std::fs::read_dir(root.join("docs"))
        .unwrap()
        .map(|entry| entry.unwrap().path())
        .filter(|path| path.extension().is_some_and(|e| e == "md"))
        .collect();
    pages.sort();
    pages.insert(0, root.join("README.md"));
    pages
        .iter()
        .map(|page| std::fs::read_to_string(page).unwrap())
        .collect::<Vec<_>>()
        .join("\n")
}

/// Fails unless the README quotes `command` (with the sample's path as it gives it).
fn assert_quoted(readme: &str, command: &str) {
    assert!(
        readme.contains(command),
        "neither the README nor docs/ quotes `{command}` any more: update this test with it"
    );
}

/// Compares a picture a quoted command drew with the README's, or rewrites the
/// README's under TRAVMAP_BLESS=1.
fn check_picture(drawn: &Path, fixture: &str) {
    let fixture = Path::new(env!("CARGO_MANIFEST_DIR")).join(fixture);
    let drawn = std::fs::read(drawn).unwrap();
    if std::env::var("TRAVMAP_BLESS").as_deref() == Ok("1") {
        std::fs::write(&fixture, &drawn).unwrap();
        eprintln!("TRAVMAP_BLESS=1: wrote {}", fixture.display());
        return;
    }
    assert!(
        std::fs::read(&fixture).unwrap() == drawn,
        "{} is stale: the README's command draws another picture; redraw it with TRAVMAP_BLESS=1 cargo test --release --test integration readme::",
        fixture.display()
    );
}

#[test]
fn the_pictures_are_what_the_quoted_commands_draw() {
    let Some(seq) = crate::common::sample() else {
        return;
    };
    let readme = readme();
    let dir = tempfile::tempdir().unwrap();
    assert_quoted(
        &readme,
        "travmap render ../shared/data/semantickitti-00/sequences/00 --frame 2 -o frame.png",
    );
    let frame = dir.path().join("frame.png");
    success(travmap(&[
        "render",
        arg(&seq),
        "--frame",
        "2",
        "-o",
        arg(&frame),
        "-q",
    ]));
    check_picture(&frame, "fixtures/semantickitti-00-frame-2.png");

    assert_quoted(
        &readme,
        "travmap map ../shared/data/semantickitti-00/sequences/00 -o drive.png --cells drive.parquet",
    );
    let (map, cells) = (
        dir.path().join("drive.png"),
        dir.path().join("drive.parquet"),
    );
    success(travmap(&[
        "map",
        arg(&seq),
        "-o",
        arg(&map),
        "--cells",
        arg(&cells),
        "-q",
    ]));
    check_picture(&map, "fixtures/semantickitti-00-drive-map.png");
}

/// A row of the README's cross-validation table: its label, the seven scores in
/// percent with one decimal and the scored cells with a thousands separator.
fn table_row(label: &str, scores: &Value, cells: u64) -> String {
    let percent: Vec<String> = ["accuracy", "miou", "f1", "fpr", "tpr", "fnr", "tnr"]
        .iter()
        .map(|k| format!("{:.1}", 100.0 * scores[k].as_f64().unwrap()))
        .collect();
    let cells = match cells {
        1000.. => format!("{},{:03}", cells / 1000, cells % 1000),
        _ => cells.to_string(),
    };
    format!("| {label} | {} | {cells} |", percent.join(" | "))
}

/// Runs `crossval` as the README says and checks its default rows (after the filter
/// and SVM only) against the README's table.
fn check_crossval_rows(settings: &[&str], filtered_label: &str, svm_label: &str) {
    let Some(seq) = crate::common::sample() else {
        return;
    };
    let readme = readme();
    let quoted = match settings {
        [] => "`travmap crossval ../shared/data/semantickitti-00/sequences/00`".to_string(),
        _ => format!("`--set {}`", settings.join(" --set ")),
    };
    assert_quoted(&readme, &quoted);
    let mut args = vec!["crossval", arg(&seq), "--json", "-q"];
    for setting in settings {
        args.extend(["--set", setting]);
    }
    let doc: Value = serde_json::from_str(&success(travmap(&args))).unwrap();
    let evaluation = &doc["report"]["evaluation"];
    let confusion = &evaluation["confusion"];
    let cells = ["tp", "tn", "fp", "fn"]
        .iter()
        .map(|k| confusion[k].as_u64().unwrap())
        .sum();
    let mut stale = Vec::new();
    for (label, scores) in [
        (filtered_label, &evaluation["scores"]),
        (svm_label, &evaluation["unfiltered_scores"]),
    ] {
        let row = table_row(label, scores, cells);
        if !readme.contains(&row) {
            stale.push(row);
        }
    }
    assert!(
        stale.is_empty(),
        "docs/method.md's table is stale; crossval now prints:\n{}",
        stale.join("\n")
    );
}

#[test]
fn the_12_m_rows_are_what_crossval_prints() {
    check_crossval_rows(
        &[],
        "12 m (the paper's), reduced set (default), after filter",
        "12 m, reduced set, SVM only",
    );
}

#[test]
fn the_36_m_rows_are_what_crossval_prints() {
    check_crossval_rows(
        &["grid.size_m=36"],
        "36 m, reduced set (default), after filter",
        "36 m, reduced set, SVM only",
    );
}

#[test]
fn the_held_out_scores_are_what_crossval_prints() {
    let (Some(s0), Some(s7)) = (
        crate::common::sample(),
        crate::common::shared_data("semantickitti-07-000964/sequences/07"),
    ) else {
        return;
    };
    let readme = readme();
    assert_quoted(
        &readme,
        r#"travmap crossval $S0 $S7 --set grid.size_m=40 --set training.grid_size_m=40 --set "$G" --set "$W""#,
    );
    let settings = [
        "grid.size_m=40",
        "training.grid_size_m=40",
        r#"features.groups=["remission"]"#,
        r#"training.class_weights="balanced""#,
    ];
    let mut args = vec!["crossval", arg(&s0), arg(&s7), "--json", "-q"];
    for setting in &settings {
        args.extend(["--set", setting]);
    }
    let doc: Value = serde_json::from_str(&success(travmap(&args))).unwrap();
    let column = |held_out: usize, key: &str| {
        let scores = &doc["report"]["held_out"][held_out]["evaluation"]["scores"];
        format!("{:.1}", 100.0 * scores[key].as_f64().unwrap())
    };
    let cell = |held_out| {
        ["accuracy", "miou", "f1", "tnr"]
            .map(|key| column(held_out, key))
            .join(" / ")
    };
    // The ablation table's default row: (b) held out seq 00, then seq 07.
    let row = format!(
        "| the same with curvity and the normal's x, y left out (**default**) | **93.7 / 85.8 / 95.6 / 85.7** | **{}** | {} |",
        cell(0),
        cell(1)
    );
    assert!(
        readme.contains(&row),
        "docs/method.md's default row should read:\n{row}"
    );
    let summary = format!(
        "held out (on a 40 m grid), each scores mIoU {} / {}",
        column(0, "miou"),
        column(1, "miou")
    );
    assert!(
        readme.contains(&summary),
        "the README's status should say: {summary}"
    );
}

#[test]
fn the_configuration_in_the_guide_is_what_travmap_config_prints() {
    let printed = success(travmap(&["config"]));
    let guide = readme();
    let start = guide
        .find("```toml\n[integration]")
        .expect("docs/guide.md no longer shows the configuration")
        + "```toml\n".len();
    let shown = &guide[start..start + guide[start..].find("```").unwrap()];
    assert_eq!(
        shown, printed,
        "docs/guide.md's configuration is not what `travmap config` prints: paste it again"
    );
}

#[test]
fn every_labelled_set_scores_what_the_docs_say() {
    let readme = readme();
    let (mut stale, mut checked) = (Vec::new(), 0);
    // The table's columns after the set and its labels: the model, the rule it is
    // scored by, and whether it is adapted first.
    let columns = [
        ("road", "road", None),
        ("road", "road", Some("--adapt")),
        ("offroad", "offroad", None),
        ("offroad", "offroad", Some("--adapt")),
        ("road", "offroad", None),
        ("offroad", "road", None),
    ];
    for line in readme.lines() {
        let cells: Vec<&str> = line
            .split(" | ")
            .map(|c| c.trim_matches('|').trim())
            .collect();
        let [set, labels, quoted @ ..] = &cells[..] else {
            continue;
        };
        if !["semantickitti", "rellis3d", "nuscenes"].contains(labels) || quoted.len() != 6 {
            continue;
        }
        let relative = match *labels {
            "nuscenes" => set.to_string(),
            _ if set.starts_with("semantickitti-07") => format!("{set}/sequences/07"),
            _ => format!("{set}/sequences/00"),
        };
        let Some(path) = crate::common::shared_data(&relative) else {
            return;
        };
        let labels_setting = format!("ground_truth.labels=\"{labels}\"");
        for ((model, rule, adapt), quoted) in columns.iter().zip(quoted) {
            let rule_setting = format!("ground_truth.rule=\"{rule}\"");
            let mut args = vec![
                "eval",
                arg(&path),
                "--model",
                model,
                "--set",
                &labels_setting,
                "--set",
                &rule_setting,
                "--json",
                "-q",
            ];
            args.extend(*adapt);
            let doc: Value = serde_json::from_str(&success(travmap(&args))).unwrap();
            let miou = format!(
                "{:.1}",
                100.0 * doc["report"]["scores"]["miou"].as_f64().unwrap()
            );
            if &miou != quoted {
                let how = adapt.unwrap_or("");
                stale.push(format!(
                    "{set}, {model} model, {rule} rule {how}: {miou}, the docs say {quoted}"
                ));
            }
        }
        checked += 1;
    }
    assert_eq!(
        checked, 9,
        "docs/method.md's table of every labelled set has 9 rows"
    );
    assert!(
        stale.is_empty(),
        "docs/method.md's table of every labelled set is stale:\n{}",
        stale.join("\n")
    );
}
