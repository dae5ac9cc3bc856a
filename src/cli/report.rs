//! What commands print: the `--json` records (one convention for all), the
//! `wrote ...` line, counts in words and notices.

use std::path::Path;

use anyhow::Result;
use serde_json::json;
use travmap_core::Config;
use travmap_core::config::{ForeignRemissionPolicy, LabelRule, LabelSet};
use travmap_method::classifier::SvmModel;
use travmap_run::DriveRun;
use travmap_run::scoring::evaluation::{
    EvaluationReport, Fit, POOR_FIT_UNSURE_SHARE, UNSURE_MARGIN,
};

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

/// `n noun` with the noun in the plural unless n is 1.
pub fn counted<N: Copy + std::fmt::Display + TryInto<u64>>(n: N, noun: &str) -> String {
    match n.try_into().ok() {
        Some(1) => format!("1 {noun}"),
        _ => format!("{n} {noun}s"),
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

/// What a report says of frames whose remission lay far outside the model's
/// training range (another sensor's scale), when there were some.
/// What a command that classifies says of the drives on stderr, even with -q: labels
/// of ids the label set does not define, remission it could not use or of another
/// sensor's scale, and a poor fit (each looks like a bad model otherwise).
pub fn notice_drives(report: &EvaluationReport, model: &SvmModel, config: &Config) {
    notice_unknown_labels(report, config);
    let remission = without_remission_said(report)
        .into_iter()
        .chain(foreign_remission_said(report, config));
    for said in remission.chain(fit_said(&report.fit, model).1) {
        eprintln!("notice: {said}");
    }
}

/// How well the drives fit the model, in a line; and when poorly, what to do about it.
pub fn fit_said(fit: &Fit, model: &SvmModel) -> (String, Option<String>) {
    let share = format!(
        "{:.1} % of {} predicted cells within the model's margin (|margin| < {UNSURE_MARGIN})",
        100.0 * fit.unsure_share,
        fit.cells
    );
    let line = format!(
        "fit: {share}; drives like its training ones: at most {:.0} %",
        100.0 * POOR_FIT_UNSURE_SHARE
    );
    let other = match model.config.ground_truth.rule {
        LabelRule::Road => LabelRule::Offroad,
        LabelRule::Offroad => LabelRule::Road,
    };
    let notice = fit.poor.then(|| {
        format!(
            "these drives fit the model poorly ({share}; its training drives: at most {:.0} %): expect scores below its own; adapt it to them (--adapt), try the {} model if the robot's ground is {} (--model {}), or train on labelled scans of this sensor",
            100.0 * POOR_FIT_UNSURE_SHARE,
            other.name(),
            match other {
                LabelRule::Offroad => "grass, dirt or low vegetation",
                LabelRule::Road => "a car's road",
            },
            other.name(),
        )
    });
    (line, notice)
}

/// What is said when the scores count another rule of what is traversable than the
/// model learnt (the off-road model scored by the road rule looks like a bad model).
pub fn other_rule_said(model: &SvmModel, config: &Config) -> Option<String> {
    let (learnt, scored) = (model.config.ground_truth.rule, config.ground_truth.rule);
    let by_preset = |c: &Config| {
        c.ground_truth.label_map.is_none() && c.ground_truth.traversable_classes.is_none()
    };
    (learnt != scored && by_preset(&model.config) && by_preset(config)).then(|| {
        format!(
            "the model learnt the {} rule of what is traversable, these scores count the {} rule (--set ground_truth.rule=\"{}\" scores it by its own)",
            learnt.name(),
            scored.name(),
            learnt.name()
        )
    })
}

/// What is said when frames had no usable remission, and why when some of it was
/// NaN or infinite (a frame that looks fine but lost its remission features).
pub fn without_remission_said(report: &EvaluationReport) -> Option<String> {
    if report.frames_without_remission == 0 {
        return None;
    }
    let why = match report.non_finite_remission_points {
        0 => String::new(),
        points => format!("; {points} points' remission was NaN or infinite"),
    };
    Some(format!(
        "{} had no usable remission (intensity{why}): the model's fallback without remission features classified them",
        counted(report.frames_without_remission, "frame")
    ))
}

pub fn foreign_remission_said(report: &EvaluationReport, config: &Config) -> Option<String> {
    let foreign = report.foreign_remission?;
    Some(format!(
        "{} had remission far outside the model's training range (median cell {:.4}, the model learnt {:.2} +- {:.2}: another sensor's scale?): {}",
        counted(report.frames_foreign_remission, "frame"),
        foreign.median,
        foreign.trained_mean,
        foreign.trained_std,
        match config.classifier.foreign_remission {
            ForeignRemissionPolicy::Notice => {
                "classified as read (--set classifier.foreign_remission=\"fallback\" classifies them without remission)"
            }
            ForeignRemissionPolicy::Fallback => {
                "the model's fallback without remission classified them"
            }
        }
    ))
}

/// Says on stderr (even with -q) when labels carried ids the label set does not
/// define: a run scored against another dataset's labels looks like a bad model.
pub fn notice_unknown_labels(report: &EvaluationReport, config: &Config) {
    let unknown = &report.unknown_labels;
    if unknown.points == 0 {
        return;
    }
    let ids: Vec<String> = unknown.examples.iter().map(u16::to_string).collect();
    let truth = &config.ground_truth;
    let label_set = match &truth.label_map {
        Some(path) => format!("label map {}", path.display()),
        None => format!("{} label set", truth.labels.name()),
    };
    // The presets that define every id seen (the unknown ones among them).
    let fitting: Vec<&str> = (LabelSet::ALL.iter())
        .filter(|set| truth.label_map.is_some() || **set != truth.labels)
        .filter(|set| unknown.examples.iter().all(|&id| set.defines(id)))
        .map(|set| set.name())
        .collect();
    let which = match fitting.as_slice() {
        [] => "--set ground_truth.labels=..., or a label_map".to_string(),
        [one] => format!("they fit the {one} label set: --set ground_truth.labels={one}"),
        several => format!(
            "they fit the {} label sets: --set ground_truth.labels=...",
            several.join(" and ")
        ),
    };
    eprintln!(
        "notice: {} labelled points in {} carry ids the {label_set} does not define (e.g. {}): they count as not traversable; are these another dataset's labels ({which})?",
        unknown.points,
        counted(report.frames_with_unknown_labels, "frame"),
        ids.join(", ")
    );
}
