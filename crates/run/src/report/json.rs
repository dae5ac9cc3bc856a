//! `--json` records, one convention for every command (docs/guide.md "Scripting with
//! `--json`"): JSON Lines, a `frame` record per frame where a command streams frames,
//! then one flat `summary` record naming the command, its `inputs` (always a list of
//! {path, frames: {start, end, count}}), the frames it `skipped`, what it `lost` and,
//! for a command that writes, its `output` (what -o named) and `outputs` (every file
//! written); an `error` record when it fails.

use std::path::Path;

use serde_json::{Value, json};
use travmap_method::classifier::SvmModel;

use crate::DriveRun;

/// The major version of every command's `--json` schema (`schemas/json/`): raised
/// when a record changes shape (2: the summary's figures at its top level, every
/// duration in `_ms`).
pub const SCHEMA_VERSION: u32 = 2;

/// A `frame` record of `fields`.
pub fn frame_record(mut fields: Value) -> Value {
    fields["type"] = "frame".into();
    fields
}

/// The `summary` record: `fields` with the command, the inputs (unless `fields`
/// names them), the files written, what was lost and the skipped frames.
pub fn summary_record(command: &str, selections: &[DriveRun], mut fields: Value) -> Value {
    fields["type"] = "summary".into();
    fields["command"] = command.into();
    fields["schema_version"] = SCHEMA_VERSION.into();
    if fields.get("inputs").is_none() {
        fields["inputs"] = selections.iter().map(input_json).collect::<Vec<_>>().into();
    }
    if let (Some(output), None) = (fields.get("output"), fields.get("outputs")) {
        fields["outputs"] = json!([output]);
    }
    fields["lost"] = selections
        .iter()
        .flat_map(|s| {
            let input = path_text(s.source.path());
            (s.source.lost().iter()).map(move |why| json!({"input": input, "reason": why}))
        })
        .collect::<Vec<_>>()
        .into();
    fields["skipped"] = selections
        .iter()
        .flat_map(|s| {
            let input = path_text(s.source.path());
            s.source.skipped().into_iter().map(
                move |skip| json!({"input": input, "frame": skip.frame, "reason": skip.reason}),
            )
        })
        .collect::<Vec<_>>()
        .into();
    fields
}

/// The `error` record of a failed command, with the file it is about when there is
/// one and the exit code.
pub fn error_record(message: &str, file: Option<&Path>, exit_code: i32) -> Value {
    json!({
        "type": "error",
        "error": message.trim_start_matches("error: ").trim_end(),
        "file": file.map(path_text),
        "exit_code": exit_code,
    })
}

/// The model's identity: its name, SHA-256 and rule, and how it was made.
pub fn model_json(model: &SvmModel, name: &str) -> Value {
    json!({
        "name": name,
        "sha256": model.sha256_hex(),
        // The rule of what is traversable it learnt.
        "rule": model.config.ground_truth.rule.name(),
        "support_vectors": model.support_vector_count(),
        "c": model.c,
        "gamma": model.gamma,
        "trained_on": model.training.sources,
        // Whether adaptation replaced the prior, and why (adapted models only).
        "adaptation": model.training.adaptation.as_ref().and_then(|a| a.check.as_ref()),
    })
}

/// One input of a summary: its path and the frames read from it.
pub fn input_json(selection: &DriveRun) -> Value {
    let frames = selection.source.frames_in(&selection.frames);
    let range = match (frames.first(), frames.last()) {
        (Some(first), Some(last)) => json!({"start": first, "end": last, "count": frames.len()}),
        _ => json!({"start": null, "end": null, "count": 0}),
    };
    json!({"path": path_text(selection.source.path()), "frames": range})
}

/// A path as JSON text. JSON holds no bytes that are not UTF-8: those of a path
/// become U+FFFD (serde refuses such a path, and `json!` panics on the refusal).
pub fn path_text(path: &Path) -> String {
    path.to_string_lossy().into_owned()
}

/// `fields` with the command's own summary (a struct) merged in at the top level:
/// a summary record is flat, whatever type holds its numbers.
pub fn with_summary(
    mut fields: Value,
    summary: &impl serde::Serialize,
) -> serde_json::Result<Value> {
    if let Value::Object(summary) = serde_json::to_value(summary)? {
        for (key, value) in summary {
            debug_assert!(
                fields.get(&key).is_none(),
                "summary field {key} named twice"
            );
            fields[key] = value;
        }
    }
    Ok(fields)
}

/// A setting's value as the config file spells it (`miou`, `drive_and_prior`), not
/// its Rust name.
pub fn setting_word(value: &impl serde::Serialize) -> String {
    match serde_json::to_value(value) {
        Ok(Value::String(word)) => word,
        Ok(other) => other.to_string(),
        Err(_) => "?".into(),
    }
}
