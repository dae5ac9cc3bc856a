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
    let confusion = &doc["confusion"];
    let cells = ["tp", "tn", "fp", "fn"]
        .iter()
        .map(|k| confusion[k].as_u64().unwrap())
        .sum();
    let mut stale = Vec::new();
    for (label, scores) in [
        (filtered_label, &doc["scores"]),
        (svm_label, &doc["unfiltered_scores"]),
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
        let scores = &doc["held_out"][held_out]["scores"];
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

/// The README installs what CI tests: the dependency versions Cargo.lock pins.
#[test]
fn the_readme_installs_the_locked_dependencies() {
    let readme = std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("README.md"));
    let readme = readme.unwrap();
    let installs: Vec<&str> = (readme.lines())
        .filter(|l| l.contains("cargo install"))
        .collect();
    assert!(
        !installs.is_empty(),
        "the README no longer says how to install"
    );
    for line in installs {
        assert!(line.contains("--locked"), "{line}");
    }
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
            let miou = format!("{:.1}", 100.0 * doc["scores"]["miou"].as_f64().unwrap());
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

/// What docs/guide.md shows of a record: arrays cut to their first three elements,
/// numbers to four decimals, the configuration left out and the files written in
/// `dir` named as `-o` gave them.
fn as_shown(value: &Value, dir: &str) -> Value {
    match value {
        Value::Object(fields) => Value::Object(
            fields
                .iter()
                .map(|(key, value)| match key.as_str() {
                    "config" => (
                        key.clone(),
                        "(the effective configuration: `travmap config --json`)".into(),
                    ),
                    _ => (key.clone(), as_shown(value, dir)),
                })
                .collect(),
        ),
        Value::Array(items) => {
            let mut shown: Vec<Value> = items.iter().take(3).map(|v| as_shown(v, dir)).collect();
            if items.len() > 3 {
                shown.push("...".into());
            }
            Value::Array(shown)
        }
        Value::Number(n) if n.is_f64() => {
            serde_json::json!((n.as_f64().unwrap() * 1e4).round() / 1e4)
        }
        Value::String(text) => text.replace(dir, "").into(),
        other => other.clone(),
    }
}

/// `value` with every measured time or rate left out: what two runs of one binary
/// on one input print alike.
fn without_times(value: &Value) -> Value {
    let timed = |key: &str| {
        key.ends_with("_ms")
            || key.ends_with("_per_s")
            || key.ends_with("_per_second")
            || key.ends_with("_mib")
            || matches!(
                key,
                "speedup"
                    | "latency_over_floor"
                    | "recorded_s_per_wall_s"
                    | "roofline_ratio"
                    | "output_bytes"
            )
    };
    match value {
        Value::Object(fields) => Value::Object(
            fields
                .iter()
                .map(|(key, value)| match timed(key) {
                    true => (key.clone(), Value::Null),
                    false => (key.clone(), without_times(value)),
                })
                .collect(),
        ),
        Value::Array(items) => Value::Array(items.iter().map(without_times).collect()),
        other => other.clone(),
    }
}

/// Fails unless `record` keeps the `--json` convention: a summary is flat (no
/// `report`, `counts` or `evaluation` wrapper) and says its schema's version; every
/// duration is in milliseconds (no key in seconds, at any depth).
fn assert_json_convention(record: &Value, command: &str) {
    fn keys(value: &Value, found: &mut Vec<String>) {
        match value {
            Value::Object(fields) => fields.iter().for_each(|(key, value)| {
                found.push(key.clone());
                keys(value, found);
            }),
            Value::Array(items) => items.iter().for_each(|item| keys(item, found)),
            _ => {}
        }
    }
    if record["type"] == "summary" {
        assert_eq!(record["schema_version"], 2, "{command}: {record}");
        for wrapper in ["report", "counts", "evaluation"] {
            assert!(
                record.get(wrapper).is_none(),
                "{command}: `{wrapper}` in {record}"
            );
        }
    }
    let mut found = Vec::new();
    keys(record, &mut found);
    for key in found {
        let in_seconds = (key.ends_with("_s") && !key.ends_with("_per_s")) || key == "seconds";
        assert!(!in_seconds, "{command}: `{key}` is not in milliseconds");
    }
}

/// docs/guide.md's sample records, each under the command that printed it (every
/// command that prints JSON but `config`): they keep the convention, and as shown
/// differ from a run of this binary in nothing but measured times (an older model's
/// sha256 or scores fail). `TRAVMAP_BLESS=1` writes what this binary prints.
#[test]
fn the_json_samples_in_the_guide_are_what_the_commands_print() {
    if crate::common::sample().is_none() {
        return;
    }
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let path = root.join("docs/guide.md");
    let mut guide = std::fs::read_to_string(&path).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let prefix = format!("{}/", dir.path().display());
    let mut samples = 0;
    let mut stale = Vec::new();
    let mut at = 0;
    while let Some(found) = guide[at..].find("`travmap ") {
        let start = at + found + 1;
        let end = start + guide[start..].find('`').unwrap();
        let command = guide[start..end].to_string();
        at = end;
        let block = "\n\n```json\n";
        if !guide[end..].starts_with(&format!("`{block}")) || !command.contains("--json") {
            continue;
        }
        let body_start = end + 1 + block.len();
        let body_end = body_start + guide[body_start..].find("```").unwrap();
        let words: Vec<String> = command
            .split_whitespace()
            .skip(1)
            .map(|word| word.trim_matches('\''))
            .map(str::to_string)
            .collect();
        // Files the command writes go to a temporary folder, named there as shown.
        let args: Vec<String> = words
            .iter()
            .enumerate()
            .map(|(i, word)| match i > 0 && words[i - 1] == "-o" {
                true => format!("{prefix}{word}"),
                false => word.clone(),
            })
            .collect();
        let out = travmap(&args.iter().map(String::as_str).collect::<Vec<_>>());
        let printed = success(out);
        let records: Vec<Value> = printed
            .lines()
            .map(|line| serde_json::from_str(line).unwrap())
            .collect();
        records
            .iter()
            .for_each(|record| assert_json_convention(record, &command));
        assert_eq!(records.last().unwrap()["type"], "summary", "{command}");
        let shown: Vec<Value> = records.iter().map(|r| as_shown(r, &prefix)).collect();
        let text: String = shown.iter().map(|v| format!("{v}\n")).collect();
        let in_guide: Vec<Value> = guide[body_start..body_end]
            .lines()
            .map(|line| serde_json::from_str(line).unwrap())
            .collect();
        // A model a command trains records its training seconds: its sha256 differs
        // from run to run.
        let compared = |record: &Value| {
            let mut record = without_times(record);
            if matches!(record["command"].as_str(), Some("train" | "adapt")) {
                record["model"]["sha256"] = Value::Null;
            }
            record
        };
        let same = shown.len() == in_guide.len()
            && shown
                .iter()
                .zip(&in_guide)
                .all(|(a, b)| compared(a) == compared(b));
        if !same {
            stale.push(command.clone());
            guide.replace_range(body_start..body_end, &text);
        }
        samples += 1;
        at = body_start;
    }
    assert!(samples >= 10, "docs/guide.md shows {samples} JSON samples");
    if std::env::var("TRAVMAP_BLESS").as_deref() == Ok("1") {
        std::fs::write(&path, guide).unwrap();
        return;
    }
    assert!(
        stale.is_empty(),
        "docs/guide.md's JSON samples of {stale:?} are not what those commands print: write them with TRAVMAP_BLESS=1 cargo test --release --test integration readme::the_json_samples"
    );
}

/// A heading's anchor as GitHub makes it: lower case, punctuation but `-` and `_`
/// dropped, spaces as `-`.
fn anchor_of(heading: &str) -> String {
    heading
        .trim()
        .to_lowercase()
        .chars()
        .filter(|c| c.is_alphanumeric() || matches!(c, ' ' | '-' | '_'))
        .map(|c| if c == ' ' { '-' } else { c })
        .collect()
}

/// The anchors of a Markdown page's headings (outside code blocks).
fn anchors(page: &str) -> Vec<String> {
    let mut in_code = false;
    let mut found = Vec::new();
    for line in page.lines() {
        if line.trim_start().starts_with("```") {
            in_code = !in_code;
        } else if !in_code && line.starts_with('#') {
            found.push(anchor_of(line.trim_start_matches('#')));
        }
    }
    found
}

/// Every relative link of the README and docs/ reaches a file, and its `#anchor` a
/// heading of that page.
#[test]
fn every_relative_link_and_anchor_in_the_docs_resolves() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut pages = vec![root.join("README.md"), root.join("ARCHITECTURE.md")];
    for entry in std::fs::read_dir(root.join("docs")).unwrap() {
        let path = entry.unwrap().path();
        if path.extension().is_some_and(|e| e == "md") {
            pages.push(path);
        }
    }
    let mut broken = Vec::new();
    for page in &pages {
        let text = std::fs::read_to_string(page).unwrap();
        let mut rest = text.as_str();
        while let Some(at) = rest.find("](") {
            rest = &rest[at + 2..];
            let Some(end) = rest.find(')') else { break };
            let target = &rest[..end];
            rest = &rest[end..];
            if target.contains("://") || target.starts_with("mailto:") || target.contains(' ') {
                continue;
            }
            let (file, anchor) = target.split_once('#').unwrap_or((target, ""));
            let linked = match file {
                "" => page.clone(),
                file => page.parent().unwrap().join(file),
            };
            if !linked.exists() {
                broken.push(format!("{}: {target} (no such file)", page.display()));
                continue;
            }
            let is_page = linked.extension().is_some_and(|e| e == "md");
            if !anchor.is_empty() && is_page {
                let headings = anchors(&std::fs::read_to_string(&linked).unwrap());
                if !headings.iter().any(|h| h == anchor) {
                    broken.push(format!("{}: {target} (no such heading)", page.display()));
                }
            }
        }
    }
    assert!(broken.is_empty(), "broken links:\n{}", broken.join("\n"));
}
