//! What commands print: the `--json` records (one convention for all), the
//! `wrote ...` line, counts in words and notices.

use std::path::Path;

use anyhow::Result;
use serde_json::json;
use travmap_core::Config;
use travmap_method::classifier::SvmModel;
use travmap_run::DriveRun;
use travmap_run::scoring::evaluation::EvaluationReport;
pub use travmap_run::scoring::remarks::{
    counted, fit_said, foreign_remission_said, other_rule_said, without_remission_said,
};
use travmap_run::scoring::remarks::{drive_notices, unknown_labels_said};

/// The model's identity in JSON outputs.
pub fn model_json(model: &SvmModel, name: &str) -> serde_json::Value {
    json!({
        "name": name,
        "sha256": model.sha256_hex(),
        "support_vectors": model.support_vector_count(),
        "c": model.c,
        "gamma": model.gamma,
        "trained_on": model.training.sources,
        // Whether adaptation replaced the prior, and why (adapted models only).
        "adaptation": model.training.adaptation.as_ref().and_then(|a| a.check.as_ref()),
    })
}

/// `--json` output, one convention for every command (docs/guide.md "Scripting with
/// `--json`", schemas in `schemas/json/`): JSON Lines on stdout, a `frame` record per
/// frame where a command streams frames, then one flat `summary` record naming the
/// command, its `inputs` (always a list of {path, frames: {start, end, count}}),
/// the frames it `skipped` and, for a command that writes, its `output` (what -o
/// named) and `outputs` (every file written).
pub fn print_json_frame(mut fields: serde_json::Value) -> Result<()> {
    fields["type"] = "frame".into();
    print_json_line(&fields)
}

/// The major version of every command's `--json` schema (`schemas/json/`): raised
/// when a record changes shape (2: the summary's figures at its top level, every
/// duration in `_ms`).
pub const SCHEMA_VERSION: u32 = 2;

/// The `summary` record of [`print_json_frame`]'s convention: `fields` with the
/// command, the inputs (unless `fields` names them) and the skipped frames.
pub fn print_json_summary(
    command: &str,
    selections: &[DriveRun],
    mut fields: serde_json::Value,
) -> Result<()> {
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
            let input = s.source.path().display().to_string();
            (s.source.lost().iter()).map(move |why| json!({"input": input, "reason": why}))
        })
        .collect::<Vec<_>>()
        .into();
    fields["skipped"] = selections
        .iter()
        .flat_map(|s| {
            let input = s.source.path().display().to_string();
            s.source.skipped().into_iter().map(
                move |skip| json!({"input": input, "frame": skip.frame, "reason": skip.reason}),
            )
        })
        .collect::<Vec<_>>()
        .into();
    print_json_line(&fields)
}

/// A path as JSON text. JSON holds no bytes that are not UTF-8: those of a path
/// become U+FFFD (serde refuses such a path, and `json!` panics on the refusal).
pub fn path_text(path: &Path) -> String {
    path.to_string_lossy().into_owned()
}

/// One input of a `--json` summary: its path and the frames read from it.
pub fn input_json(selection: &DriveRun) -> serde_json::Value {
    let frames = selection.source.frames_in(&selection.frames);
    let range = match (frames.first(), frames.last()) {
        (Some(first), Some(last)) => json!({"start": first, "end": last, "count": frames.len()}),
        _ => json!({"start": null, "end": null, "count": 0}),
    };
    json!({"path": path_text(selection.source.path()), "frames": range})
}

/// `fields` with the command's own summary (a struct) merged in at the top level:
/// a summary record is flat, whatever type holds its numbers.
pub fn with_summary(
    mut fields: serde_json::Value,
    summary: &impl serde::Serialize,
) -> Result<serde_json::Value> {
    if let serde_json::Value::Object(summary) = serde_json::to_value(summary)? {
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
        Ok(serde_json::Value::String(word)) => word,
        Ok(other) => other.to_string(),
        Err(_) => "?".into(),
    }
}

/// The line a command that wrote an MCAP ends with:
/// `wrote PATH (N frames, CONTENTS, M MB, R frames/s)`.
pub fn print_wrote(path: &Path, frames: usize, contents: &str, bytes: u64, seconds: f64) {
    println!(
        "wrote {} ({}, {contents}, {:.1} MB, {:.1} frames/s)",
        path.display(),
        counted(frames, "frame"),
        bytes as f64 / 1e6,
        frames as f64 / seconds
    );
}

/// An error under `--json`: one `error` record on stderr, with the file it is
/// about when there is one and the exit code.
pub fn print_json_error(message: &str, file: Option<&Path>, exit_code: i32) {
    let record = json!({
        "type": "error",
        "error": message.trim_start_matches("error: ").trim_end(),
        "file": file.map(path_text),
        "exit_code": exit_code,
    });
    eprintln!("{record}");
}

fn print_json_line(value: &serde_json::Value) -> Result<()> {
    use std::io::Write;
    writeln!(std::io::stdout().lock(), "{value}")?;
    Ok(())
}

/// Says on stderr, even with -q, what the run found of the drives
/// ([`drive_notices`]).
pub fn notice_drives(report: &EvaluationReport, model: &SvmModel, config: &Config) {
    for said in drive_notices(report, model, config) {
        eprintln!("notice: {said}");
    }
}

/// Says on stderr when labels carried ids the label set does not define.
pub fn notice_unknown_labels(report: &EvaluationReport, config: &Config) {
    if let Some(said) = unknown_labels_said(report, config) {
        eprintln!("notice: {said}");
    }
}
