//! Golden test (STYLE.md, tests in layers): `travmap annotate` of the shipped
//! SemanticKITTI sample, frames 0..3, dumped to a small JSON and compared with
//! `fixtures/golden-annotate-00.json`.
//!
//! The dump holds what a run must reproduce bit for bit: per frame the predicted and
//! ground-truth OccupancyGrids (header, geometry, cell counts and a SHA-256 of the
//! cells), the frame's in-grid cloud (point count, fields, SHA-256 of its bytes) and every
//! FrameMetrics field except `latency_ms`, which is a measured time. A change of any
//! of them fails with the list of what changed; when the change is intended,
//! `TRAVMAP_BLESS=1 cargo test --release --test golden` rewrites the fixture (see
//! fixtures/README.md).

use std::collections::BTreeMap;
use std::path::Path;

use serde_json::{Value, json};
use sha2::{Digest, Sha256};
use travmap_formats::ros::{FrameMetrics, OccupancyGrid, PointCloud2, Time, decode};
use travmap_outputs::annotation::{
    CLOUD_TOPIC, GROUND_TRUTH_TOPIC, METRICS_TOPIC, PREDICTION_TOPIC,
};

const FIXTURE: &str = "fixtures/golden-annotate-00.json";
const FRAMES: &str = "0..3";

fn sha256_hex(bytes: &[u8]) -> String {
    Sha256::digest(bytes)
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect()
}

/// An f32 as the JSON number of its shortest decimal form (0.4, not
/// 0.4000000059604645), which reads back to the same f32; NaN (no ground truth) as
/// null.
fn f32_value(x: f32) -> Value {
    if x.is_finite() {
        // The shortest form of a finite f32 always parses as an f64.
        json!(x.to_string().parse::<f64>().unwrap())
    } else {
        Value::Null
    }
}

fn stamp(t: Time) -> Value {
    json!({ "sec": t.sec, "nanosec": t.nanosec })
}

fn grid(g: &OccupancyGrid) -> Value {
    let count = |v: i8| g.data.iter().filter(|&&c| c == v).count();
    let other = g.data.len() - count(-1) - count(0) - count(100);
    let bytes: Vec<u8> = g.data.iter().map(|&c| c as u8).collect();
    json!({
        "stamp": stamp(g.header.stamp),
        "frame_id": g.header.frame_id,
        "resolution": f32_value(g.info.resolution),
        "width": g.info.width,
        "height": g.info.height,
        "origin": g.info.origin,
        "cells": { "unknown": count(-1), "free": count(0), "occupied": count(100), "other": other },
        "sha256": sha256_hex(&bytes),
    })
}

fn cloud(c: &PointCloud2) -> Value {
    json!({
        "stamp": stamp(c.header.stamp),
        "frame_id": c.header.frame_id,
        "points": c.width as u64 * c.height as u64,
        "fields": c.fields.iter().map(|f| f.name.as_str()).collect::<Vec<_>>(),
        "sha256": sha256_hex(&c.data),
    })
}

/// Every field but `latency_ms`, a measured time.
fn metrics(m: &FrameMetrics) -> Value {
    json!({
        "stamp": stamp(m.header.stamp),
        "frame_id": m.header.frame_id,
        "frame_index": m.frame_index,
        "predictable_cells": m.predictable_cells,
        "traversable_cells": m.traversable_cells,
        "non_traversable_cells": m.non_traversable_cells,
        "has_ground_truth": m.has_ground_truth,
        "true_positives": m.true_positives,
        "true_negatives": m.true_negatives,
        "false_positives": m.false_positives,
        "false_negatives": m.false_negatives,
        "unpredictable_with_ground_truth": m.unpredictable_with_ground_truth,
        "accuracy": f32_value(m.accuracy),
        "miou": f32_value(m.miou),
        "f1": f32_value(m.f1),
        "dropped_points": m.dropped_points,
        "unsure_cells": m.unsure_cells,
    })
}

/// The golden summary of an annotated MCAP: message counts per topic, the model's
/// hash, and per frame (by log time, which is the frame's stamp) its four messages.
fn summarise(path: &Path) -> Value {
    let bytes = std::fs::read(path).unwrap();
    let mut topics: BTreeMap<String, usize> = BTreeMap::new();
    let mut frames: BTreeMap<u64, BTreeMap<&str, Value>> = BTreeMap::new();
    for message in mcap::MessageStream::new(&bytes).unwrap() {
        let message = message.unwrap();
        let topic = message.channel.topic.as_str();
        *topics.entry(topic.to_string()).or_default() += 1;
        let (key, value) = match topic {
            PREDICTION_TOPIC => ("prediction", grid(&decode(&message.data).unwrap())),
            GROUND_TRUTH_TOPIC => ("ground_truth", grid(&decode(&message.data).unwrap())),
            CLOUD_TOPIC => ("cloud", cloud(&decode(&message.data).unwrap())),
            METRICS_TOPIC => ("metrics", metrics(&decode(&message.data).unwrap())),
            _ => continue,
        };
        let previous = frames
            .entry(message.log_time)
            .or_default()
            .insert(key, value);
        assert!(
            previous.is_none(),
            "two {topic} messages at {}",
            message.log_time
        );
    }
    let metadata = crate::common::travmap_metadata(&bytes);
    json!({
        "command": format!("travmap annotate <semantickitti-00>/sequences/00 --frames {FRAMES} --no-passthrough -q"),
        "model_sha256": metadata["model_sha256"],
        "topics": topics,
        // A frame without ground truth has no ground_truth key.
        "frames": frames.into_values().collect::<Vec<_>>(),
    })
}

/// Checks that hold whatever the fixture says, so that blessing cannot record output
/// that contradicts itself: each frame has a prediction, a cloud and metrics; the
/// metrics' cell counts are the prediction's; a ground-truth grid exists exactly when
/// the metrics say so, and its known cells are the confusion matrix's total.
fn check_consistency(summary: &Value) {
    for (i, frame) in summary["frames"].as_array().unwrap().iter().enumerate() {
        let (prediction, metrics) = (&frame["prediction"], &frame["metrics"]);
        assert!(
            prediction.is_object() && frame["cloud"].is_object() && metrics.is_object(),
            "frame {i}: {frame}"
        );
        let cells = &prediction["cells"];
        assert_eq!(metrics["traversable_cells"], cells["free"], "frame {i}");
        assert_eq!(
            metrics["non_traversable_cells"], cells["occupied"],
            "frame {i}"
        );
        assert_eq!(cells["other"], 0, "frame {i}: cells neither -1, 0 nor 100");
        let truth = &frame["ground_truth"];
        assert_eq!(metrics["has_ground_truth"], truth.is_object(), "frame {i}");
        if truth.is_object() {
            let count = |key: &str| metrics[key].as_u64().unwrap();
            let confusion = [
                "true_positives",
                "true_negatives",
                "false_positives",
                "false_negatives",
            ]
            .map(count);
            let known = truth["cells"]["free"].as_u64().unwrap()
                + truth["cells"]["occupied"].as_u64().unwrap();
            assert_eq!(
                confusion.iter().sum::<u64>() + count("unpredictable_with_ground_truth"),
                known,
                "frame {i}"
            );
        }
    }
}

/// The fixture's text: JSON, indented down to each message, and each message on one
/// line, so that the file stays small and a diff still names the message.
fn fixture_text(value: &Value, depth: usize) -> String {
    let indent = |d: usize| "  ".repeat(d);
    match value {
        Value::Object(map) if depth < 3 && !map.is_empty() => {
            let entries: Vec<String> = map
                .iter()
                .map(|(k, v)| {
                    format!(
                        "{}{}: {}",
                        indent(depth + 1),
                        Value::from(k.as_str()),
                        fixture_text(v, depth + 1)
                    )
                })
                .collect();
            format!("{{\n{}\n{}}}", entries.join(",\n"), indent(depth))
        }
        Value::Array(items) if depth < 3 && !items.is_empty() => {
            let entries: Vec<String> = items
                .iter()
                .map(|v| format!("{}{}", indent(depth + 1), fixture_text(v, depth + 1)))
                .collect();
            format!("[\n{}\n{}]", entries.join(",\n"), indent(depth))
        }
        _ => value.to_string(),
    }
}

/// Where `actual` differs from `expected`, one line per JSON path.
fn differences(path: &str, expected: &Value, actual: &Value, out: &mut Vec<String>) {
    match (expected, actual) {
        (Value::Object(e), Value::Object(a)) => {
            for key in e.keys().chain(a.keys().filter(|k| !e.contains_key(*k))) {
                let null = Value::Null;
                let (ev, av) = (e.get(key).unwrap_or(&null), a.get(key).unwrap_or(&null));
                differences(&format!("{path}.{key}"), ev, av, out);
            }
        }
        (Value::Array(e), Value::Array(a)) if e.len() == a.len() => {
            for (i, (ev, av)) in e.iter().zip(a).enumerate() {
                differences(&format!("{path}[{i}]"), ev, av, out);
            }
        }
        _ if expected != actual => out.push(format!("{path}: expected {expected}, got {actual}")),
        _ => {}
    }
}

#[test]
fn annotate_of_semantickitti_00_frames_0_to_3_matches_the_golden_file() {
    let dir = tempfile::tempdir().unwrap();
    let flags = ["--frames", FRAMES, "--no-passthrough"];
    let Some((_, output)) = crate::common::sample_annotated(dir.path(), &flags) else {
        return;
    };
    let actual = summarise(&output);
    check_consistency(&actual);
    let fixture = Path::new(env!("CARGO_MANIFEST_DIR")).join(FIXTURE);

    if std::env::var("TRAVMAP_BLESS").as_deref() == Ok("1") {
        let text = fixture_text(&actual, 0) + "\n";
        std::fs::write(&fixture, text).unwrap();
        eprintln!("TRAVMAP_BLESS=1: wrote {}", fixture.display());
        return;
    }
    let text = std::fs::read_to_string(&fixture).unwrap_or_else(|e| {
        panic!(
            "{}: {e}; to create it: TRAVMAP_BLESS=1 cargo test --release --test golden",
            fixture.display()
        )
    });
    let expected: Value = serde_json::from_str(&text).unwrap();
    let mut changed = Vec::new();
    differences("$", &expected, &actual, &mut changed);
    assert!(
        changed.is_empty(),
        "annotate output differs from {FIXTURE} in {} places:\n{}\n\
         If the change is intended: TRAVMAP_BLESS=1 cargo test --release --test golden, \
         and commit the fixture with the change.",
        changed.len(),
        changed.join("\n")
    );
}
