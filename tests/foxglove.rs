//! `foxglove/layout.json` opens what travmap writes: every topic, plotted field,
//! colour field and frame it names exists in an annotated file of the shipped data.

use std::collections::BTreeSet;
use std::path::Path;

use serde_json::Value;
use travmap_formats::ros::{PointCloud2, TfMessage, decode};

fn layout() -> Value {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("foxglove/layout.json");
    serde_json::from_slice(&std::fs::read(path).unwrap()).unwrap()
}

/// The panel ids in the layout tree.
fn panels(node: &Value, out: &mut BTreeSet<String>) {
    match node {
        Value::String(id) => {
            out.insert(id.clone());
        }
        Value::Object(split) => {
            panels(&split["first"], out);
            panels(&split["second"], out);
        }
        other => panic!("unexpected layout node {other}"),
    }
}

#[test]
fn every_panel_in_the_tree_is_configured_and_every_configuration_is_shown() {
    let layout = layout();
    let mut shown = BTreeSet::new();
    panels(&layout["layout"], &mut shown);
    let configured: BTreeSet<String> = layout["configById"]
        .as_object()
        .unwrap()
        .keys()
        .cloned()
        .collect();
    assert_eq!(shown, configured);
}

#[test]
fn the_layout_names_topics_fields_and_frames_of_an_annotated_file() {
    let dir = tempfile::tempdir().unwrap();
    let Some((_, out)) = crate::common::sample_annotated(dir.path(), &["--frames", "0..3"]) else {
        return;
    };
    let bytes = std::fs::read(&out).unwrap();
    let mut topics = BTreeSet::new();
    let mut frames = BTreeSet::new();
    let mut cloud_fields = BTreeSet::new();
    let mut metrics_schema = String::new();
    for message in mcap::MessageStream::new(&bytes).unwrap() {
        let message = message.unwrap();
        let topic = message.channel.topic.clone();
        if topic == "/tf" || topic == "/tf_static" {
            for t in decode::<TfMessage>(&message.data).unwrap().transforms {
                frames.insert(t.header.frame_id);
                frames.insert(t.child_frame_id);
            }
        }
        if topic == "/travmap/cloud" {
            let cloud = decode::<PointCloud2>(&message.data).unwrap();
            cloud_fields.extend(cloud.fields.into_iter().map(|f| f.name));
        }
        if topic == "/travmap/metrics" {
            let schema = message.channel.schema.as_ref().unwrap();
            metrics_schema = String::from_utf8(schema.data.to_vec()).unwrap();
        }
        topics.insert(topic);
    }
    // The metrics message's own fields, before its nested definitions.
    let metrics_fields: BTreeSet<&str> = metrics_schema
        .split("=====")
        .next()
        .unwrap()
        .lines()
        .filter(|l| !l.starts_with('#') && !l.trim().is_empty())
        .filter_map(|l| l.split_whitespace().nth(1))
        .collect();

    let layout = layout();
    let scene = &layout["configById"]["3D!travmap"];
    assert!(
        frames.contains(scene["followTf"].as_str().unwrap()),
        "{frames:?}"
    );
    for (topic, settings) in scene["topics"].as_object().unwrap() {
        assert!(topics.contains(topic), "3D topic {topic} not in {topics:?}");
        if let Some(field) = settings.get("colorField").and_then(Value::as_str)
            && topic == "/travmap/cloud"
        {
            assert!(
                cloud_fields.contains(field),
                "{field} not in {cloud_fields:?}"
            );
        }
    }
    for plot in ["Plot!accuracy", "Plot!latency"] {
        for path in layout["configById"][plot]["paths"].as_array().unwrap() {
            let (topic, field) = path["value"].as_str().unwrap().split_once('.').unwrap();
            assert!(topics.contains(topic), "{topic}");
            assert!(
                metrics_fields.contains(field),
                "{field} not in {metrics_fields:?}"
            );
        }
    }
    // The camera topic is the one `convert` writes for image_2 (no images here).
    assert_eq!(
        layout["configById"]["Image!camera"]["imageMode"]["imageTopic"],
        travmap_outputs::conversion::IMAGE_TOPIC
    );
}
