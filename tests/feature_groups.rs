//! Remission features across sensors: a cloud without intensity runs with the
//! model's fallback and says so; intensity on Velodyne's 0..255 scale gives the same
//! grids as KITTI's 0..1.

use std::path::Path;

use travmap_formats::mcap::writer::Compression;
use travmap_formats::ros::{PointCloud2, TfMessage, datatype, decode};
use travmap_io::InputFormat;
use travmap_io::Log;
use travmap_outputs::writing::McapSink;

/// Rewrites the converted drive `from` into `to` with each cloud's intensity
/// changed by `edit` (clouds and transforms only).
fn rewrite_clouds(from: &Path, to: &Path, edit: impl Fn(&mut PointCloud2)) {
    let log = Log::open(from, InputFormat::Mcap).unwrap();
    let mut sink = McapSink::create(to, Compression::None).unwrap();
    for message in log.messages() {
        let message = message.unwrap();
        let topic = message.connection.topic.as_str();
        match message.connection.schema_name.as_str() {
            "sensor_msgs/msg/PointCloud2" => {
                let mut cloud: PointCloud2 = decode(&message.data).unwrap();
                edit(&mut cloud);
                sink.write(topic, message.log_time_ns, &cloud).unwrap();
            }
            "tf2_msgs/msg/TFMessage" => {
                let tf: TfMessage = decode(&message.data).unwrap();
                sink.write(topic, message.log_time_ns, &tf).unwrap();
            }
            _ => {}
        }
    }
    sink.finish().unwrap();
}

/// The intensity field of a converted cloud: its offset.
fn intensity_offset(cloud: &PointCloud2) -> usize {
    let field = cloud.fields.iter().find(|f| f.name == "intensity").unwrap();
    assert_eq!(field.datatype, datatype::FLOAT32);
    field.offset as usize
}

fn run_json(input: &Path) -> (Vec<serde_json::Value>, serde_json::Value, String) {
    let out = crate::common::travmap(&["run", input.to_str().unwrap(), "--json"]);
    assert!(out.status.success(), "{}", crate::common::stderr(&out));
    let (frames, summary) = crate::common::json_records(&crate::common::stdout(&out));
    (frames, summary, crate::common::stderr(&out))
}

#[test]
fn intensity_scales_and_a_cloud_without_intensity() {
    let Some(seq) = crate::common::semantickitti_00() else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let original = dir.path().join("original.mcap");
    let out = crate::common::travmap(&[
        "convert",
        seq.to_str().unwrap(),
        "-o",
        original.to_str().unwrap(),
        "-q",
    ]);
    assert!(out.status.success(), "{}", crate::common::stderr(&out));

    // Velodyne's 0..255: every intensity times 255.
    let bytes = dir.path().join("byte.mcap");
    rewrite_clouds(&original, &bytes, |cloud| {
        let at = intensity_offset(cloud);
        let step = cloud.point_step as usize;
        for point in cloud.data.chunks_exact_mut(step) {
            let raw: [u8; 4] = point[at..at + 4].try_into().unwrap();
            let scaled = f32::from_le_bytes(raw) * 255.0;
            point[at..at + 4].copy_from_slice(&scaled.to_le_bytes());
        }
    });
    // No intensity field at all (x, y, z and the label stay where they were).
    let bare = dir.path().join("bare.mcap");
    rewrite_clouds(&original, &bare, |cloud| {
        cloud.fields.retain(|f| f.name != "intensity");
    });

    let (unit_frames, unit, _) = run_json(&original);
    let (byte_frames, byte, _) = run_json(&bytes);
    assert_eq!(unit_frames.len(), 6);
    assert_eq!(unit["frames_without_remission"], 0);
    assert_eq!(byte["frames_without_remission"], 0);
    for (a, b) in unit_frames.iter().zip(&byte_frames) {
        assert_eq!(a["remission"], "unit");
        assert_eq!(b["remission"], "byte");
        assert_eq!(a["cells"], b["cells"], "frame {}", a["frame"]);
    }

    let (bare_frames, bare_summary, _) = run_json(&bare);
    assert_eq!(bare_summary["frames_without_remission"], 6);
    assert!(
        bare_frames
            .iter()
            .all(|f| f["remission"] == "missing" && f["without_remission"] == true)
    );
    // The fallback still predicts most of the street as the full model does.
    let agree: usize = unit_frames
        .iter()
        .zip(&bare_frames)
        .map(|(a, b)| {
            let (a, b) = (
                a["cells"].as_array().unwrap(),
                b["cells"].as_array().unwrap(),
            );
            a.iter().zip(b).filter(|(x, y)| x == y).count()
        })
        .sum();
    assert!(agree > 6 * 900 * 9 / 10, "{agree} of 5400 cells agree");
    // In text the fallback is said on stderr.
    let out = crate::common::travmap(&["run", bare.to_str().unwrap()]);
    let err = crate::common::stderr(&out);
    assert!(
        out.status.success() && err.contains("6 frames had no usable remission"),
        "{err}"
    );
}

/// RELLIS-3D's Ouster remission (0.0002-0.0115 in KITTI's layout), read as it is, is
/// named as foreign to a model trained on KITTI's remission as read; classified as
/// read by default, by the fallback on request. Ranked within each scan (the
/// default), it is no sensor's scale and nothing is foreign.
#[test]
fn remission_on_another_sensors_scale_is_named_and_the_fallback_is_a_setting() {
    let (Some(rellis), Some(sample)) = (
        crate::common::shared_data("rellis3d-000104/sequences/00"),
        crate::common::sample(),
    ) else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let model = dir.path().join("as_read.json");
    let as_read_scale = "features.remission_scale=\"as_read\"";
    crate::common::write_output("train", &sample, &model, &["--set", as_read_scale]);
    let model = crate::common::arg(&model);
    let as_read_args = [
        "eval",
        crate::common::arg(&rellis),
        "--model",
        model,
        "--set",
        as_read_scale,
    ];
    let eval = |extra: &[&str]| {
        let args = [&as_read_args[..], extra].concat();
        crate::common::json_summary(&args)
    };
    let ranked = crate::common::json_summary(&["eval", crate::common::arg(&rellis)]);
    assert_eq!(ranked["frames_foreign_remission"], 0);
    let as_read = eval(&[]);
    assert_eq!(as_read["frames_foreign_remission"], 1);
    let foreign = &as_read["foreign_remission"];
    assert!(foreign["median"].as_f64().unwrap() < 0.02, "{foreign}");
    assert!((foreign["trained_mean"].as_f64().unwrap() - 0.27).abs() < 0.05);
    let fallback = eval(&["--set", "classifier.foreign_remission=\"fallback\""]);
    assert_eq!(fallback["frames_foreign_remission"], 1);
    assert_ne!(fallback["confusion"], as_read["confusion"]);
    let output = crate::common::travmap(&as_read_args);
    crate::common::success(output.clone());
    crate::common::assert_contains(
        &crate::common::stderr(&output),
        &["notice: 1 frame had remission far outside the model's training range"],
    );
    // annotate says so too, on stderr.
    let annotated = dir.path().join("a.mcap");
    let annotate = [
        "annotate",
        crate::common::arg(&rellis),
        "-o",
        crate::common::arg(&annotated),
        "--model",
        model,
        "--set",
        as_read_scale,
    ];
    let out = crate::common::travmap(&annotate);
    assert!(out.status.success());
    crate::common::assert_contains(
        &crate::common::stderr(&out),
        &["notice: 1 frame had remission far outside the model's training range"],
    );
    // KITTI's own scans are not foreign to the model trained on them.
    let kitti = crate::common::json_summary(&[
        "eval",
        crate::common::arg(&sample),
        "--model",
        model,
        "--set",
        as_read_scale,
    ]);
    assert_eq!(kitti["frames_foreign_remission"], 0);
}
