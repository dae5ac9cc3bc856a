//! `travmap eval`: the paper's table (Acc, mIoU, F1, FPR, TPR, FNR, TNR, latency)
//! for the selected frames, with the geometry-only ablation when a camera saw cells.

use std::io::Write;

use anyhow::Result;
use clap::Args;
use serde_json::json;
use travmap_core::Config;
use travmap_method::classifier::SvmModel;
use travmap_run::DriveRun;
use travmap_run::report::tables::{fused_line, model_line, score_table, training_note};
use travmap_run::scoring::evaluation::{DriveScores, score_drives};
use travmap_run::scoring::remarks::FitRemedies;

use super::adapt::AdaptFlag;
use super::{
    Inputs, ModelArg, Outcome, Output, counted, fit_said, frame_count, model_json, notice_drives,
    other_rule_said, outcome, print_json_summary, with_summary,
};

/// Score predictions against SemanticKITTI ground truth (the paper's table).
#[derive(Args)]
#[command(
    after_long_help = "Examples (SEQ: a KITTI sequence folder, e.g. ../shared/data/semantickitti-00/sequences/00):\n  travmap eval SEQ\n  travmap eval rellis/sequences/00 --set ground_truth.labels=rellis3d\n  travmap eval SEQ --model my.json --json"
)]
pub struct EvalArgs {
    #[command(flatten)]
    inputs: Inputs,
    #[command(flatten)]
    model: ModelArg,
    #[command(flatten)]
    adapt: AdaptFlag,
}

pub fn eval(args: EvalArgs) -> Result<Outcome> {
    let config = &args.model.config(&args.inputs.settings)?;
    let output = args.inputs.output;
    let loaded = args.inputs.settings.load_model(config)?;
    let mut selections = args.inputs.open(config, config.appearance.enabled)?;
    // Before adapting (the longer work): a drive without labels has nothing to score.
    if args.adapt.adapt {
        for selection in &selections {
            if !selection.has_labels()? {
                return Err(nothing_to_score(std::slice::from_ref(selection)));
            }
        }
    }
    let (model, model_name) = (args.adapt).apply(&args.inputs, config, loaded, &output)?;
    let scored = score(&mut selections, config, &model, output, "evaluating")?;
    let report = &scored.report;
    if report.scored_frames == 0 {
        return Err(nothing_to_score(&selections));
    }
    // The ablation of the paper: the same frames without appearance features.
    let geometry_only = match &model.hybrid {
        Some(_) if report.frames_with_images > 0 => {
            let mut geometric = model.clone();
            geometric.hybrid = None;
            Some(score(&mut selections, config, &geometric, output, "geometry only")?.report)
        }
        _ => None,
    };
    let remedies = FitRemedies::of(&selections, true, scored.training_frames);
    notice_drives(report, &model, config, remedies);
    let fused = &scored.fused;
    let fused_scores = fused.scores_if_predicted();
    if output.json {
        let fields = json!({
            "config": config,
            "model": model_json(&model, &model_name),
            "geometry_only": geometry_only,
            "drive_map": {"confusion": fused, "scores": fused_scores},
            "training_frames_scored": scored.training_frames,
        });
        print_json_summary("eval", &selections, with_summary(fields, report)?)?;
        return Ok(outcome(&selections));
    }
    let mut out = std::io::stdout().lock();
    // `--quiet` leaves the scores: what was read and with which model is chatter.
    if !output.quiet {
        let sources: Vec<String> = selections.iter().map(DriveRun::describe).collect();
        writeln!(out, "inputs: {}", sources.join("; "))?;
        writeln!(out, "{}", model_line(&model, &model_name))?;
    }
    if let Some(said) = other_rule_said(&model, config) {
        writeln!(out, "note: {said}")?;
    }
    write!(out, "{}", score_table(report, true))?;
    if let Some(line) = fused_line(fused) {
        writeln!(out, "{line}")?;
    }
    writeln!(out, "{}", fit_said(&report.fit))?;
    if report.dropped_points > 0 {
        let were = if report.dropped_points == 1 {
            "was"
        } else {
            "were"
        };
        writeln!(
            out,
            "{} without a return (a NaN or infinite coordinate, or the sensor's origin) {were} dropped",
            counted(report.dropped_points, "point"),
        )?;
    }
    match &geometry_only {
        Some(geometric) => {
            writeln!(
                out,
                "ablation: the rows above use appearance for the {} of {} that a camera saw; without it:",
                counted(report.cells_with_appearance, "cell"),
                counted(report.frames_with_images, "frame")
            )?;
            write!(out, "{}", score_table(geometric, true))?;
        }
        None if report.frames_with_images == 0 => {
            writeln!(out, "no camera images in these frames: geometry only")?;
        }
        None => writeln!(out, "the model has no hybrid part: geometry only")?,
    }
    let note = training_note(scored.training_frames, report.scored_frames);
    writeln!(out, "{note}")?;
    Ok(outcome(&selections))
}

/// The error of drives without labels to score against.
fn nothing_to_score(selections: &[DriveRun]) -> anyhow::Error {
    let looked: Vec<String> = (selections.iter())
        .map(|s| s.source.where_labels_are_read())
        .collect();
    anyhow::anyhow!(
        "no frame of the input has labels to score against (looked for {}; a frame is scored when every scan of its window has them): nothing to score. `travmap run` classifies frames without labels",
        looked.join("; ")
    )
}

/// `model` scored on the drives, under a progress bar saying `message`.
fn score(
    selections: &mut [DriveRun],
    config: &Config,
    model: &SvmModel,
    output: Output,
    message: &str,
) -> Result<DriveScores> {
    let bar = output.progress(frame_count(selections), message);
    let scores = score_drives(selections, config, model, || bar.inc(1))?;
    bar.finish();
    Ok(scores)
}
