//! `travmap eval`: the paper's table (Acc, mIoU, F1, FPR, TPR, FNR, TNR, latency)
//! for the selected frames, with the geometry-only ablation when a camera saw cells.

use std::collections::HashSet;
use std::io::Write;

use anyhow::{Result, bail};
use clap::Args;
use serde_json::json;
use travmap_method::classifier::{AdaptationSummary, SvmModel};
use travmap_run::scoring::evaluation::{Evaluation, EvaluationReport};
use travmap_run::scoring::metrics::Confusion;
use travmap_run::scoring::metrics::Scores;
use travmap_run::{DriveRun, Fingerprints};

use super::adapt::AdaptFlag;
use super::{
    Inputs, ModelArg, Outcome, counted, fit_said, foreign_remission_said, frame_count, model_json,
    notice_unknown_labels, other_rule_said, outcome, print_json_summary, with_summary,
    without_remission_said,
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
    let config = &args.inputs.settings.load()?;
    let output = args.inputs.output;
    let (model, model_name) =
        (args.adapt).apply(&args.inputs, config, args.model.load(config)?, &output)?;
    let mut selections = args.inputs.open(config, config.appearance.enabled)?;
    // Training scans are recognised by content, not by the path as typed.
    let trained_on: HashSet<&str> = model
        .training
        .frame_sha256
        .iter()
        .map(String::as_str)
        .collect();
    for selection in &mut selections {
        if !trained_on.is_empty() {
            selection.fingerprint_scans = Fingerprints::Labelled;
        }
    }
    let evaluate = |model: &SvmModel,
                    message: &str,
                    training_frames: &mut usize|
     -> Result<(EvaluationReport, Confusion)> {
        let bar = output.progress(frame_count(&selections), message);
        let mut evaluation = Evaluation::default();
        let mut fused = Confusion::default();
        for selection in &selections {
            let drive_map =
                selection.run_mapped::<anyhow::Error>(config, Some(model), |result, _| {
                    bar.inc(1);
                    let seen = result
                        .scan_sha256
                        .as_deref()
                        .is_some_and(|s| trained_on.contains(s));
                    *training_frames += (seen && result.ground_truth.is_some()) as usize;
                    evaluation.add(&result);
                    Ok(())
                })?;
            fused.merge(&Confusion::of_drive_map(&drive_map.cells()));
        }
        bar.finish();
        Ok((evaluation.report(), fused))
    };
    let mut training_frames = 0usize;
    let (report, fused) = evaluate(&model, "evaluating", &mut training_frames)?;
    if report.scored_frames == 0 {
        let looked: Vec<String> = (selections.iter())
            .map(|s| s.source.where_labels_are_read())
            .collect();
        bail!(
            "no frame of the input has labels to score against (looked for {}; a frame is scored when every scan of its window has them): nothing to score. `travmap run` classifies frames without labels",
            looked.join("; ")
        );
    }
    // Each world cell once: the drive's fused map against its fused ground truth.
    let fused_scored = fused.tp + fused.tn + fused.fp + fused.r#fn;
    let fused_scores = (fused_scored > 0).then(|| fused.scores());
    // Training frames among the scored ones; None when the model does not say.
    let training_frames = (!trained_on.is_empty()).then_some(training_frames);
    // The ablation of the paper: the same frames without appearance features.
    let geometry_only = match &model.hybrid {
        Some(_) if report.frames_with_images > 0 => {
            let mut geometric = model.clone();
            geometric.hybrid = None;
            Some(evaluate(&geometric, "geometry only", &mut 0)?.0)
        }
        _ => None,
    };
    notice_unknown_labels(&report, config);
    let sources: Vec<String> = selections.iter().map(DriveRun::describe).collect();
    if output.json {
        let fields = json!({
            "config": config,
            "model": model_json(&model, &model_name),
            "geometry_only": geometry_only,
            "drive_map": {"confusion": fused, "scores": fused_scores},
            "training_frames_scored": training_frames,
        });
        print_json_summary("eval", &selections, with_summary(fields, &report)?)?;
        return Ok(outcome(&selections));
    }
    let mut out = std::io::stdout().lock();
    // `--quiet` leaves the scores: what was read and with which model is chatter.
    if !output.quiet {
        writeln!(out, "inputs: {}", sources.join("; "))?;
        let hybrid = match &model.hybrid {
            Some(h) => format!(
                "a hybrid model with {} support vectors for cells a camera saw",
                h.support_vector_count()
            ),
            None => "no hybrid model".into(),
        };
        let kept = |a: &AdaptationSummary| a.check.as_ref().is_some_and(|c| !c.adapted);
        let learnt = match &model.training.adaptation {
            Some(adaptation) if kept(adaptation) => format!(
                "{} as it was (adaptation's check kept it), trained on {}",
                adaptation.prior,
                model.training.sources.join("; ")
            ),
            Some(adaptation) => format!(
                "adapted to {} (no labels read) from {}",
                model.training.sources.join("; "),
                adaptation.prior
            ),
            None => format!("trained on {}", model.training.sources.join("; ")),
        };
        writeln!(
            out,
            "model: {model_name} (sha256 {}, {} support vectors, C {}, gamma {}; {hybrid}), {learnt}",
            &model.sha256_hex()[..12],
            model.support_vector_count(),
            model.c,
            model.gamma,
        )?;
    }
    if let Some(said) = other_rule_said(&model, config) {
        writeln!(out, "note: {said}")?;
    }
    write_table(&mut out, &report, true)?;
    if let Some(scores) = fused_scores {
        writeln!(
            out,
            "fused drive map ({fused_scored} world cells, each once): Acc {:.1} mIoU {:.1} F1 {:.1} FPR {:.1} TPR {:.1}",
            scores.accuracy * 100.0,
            scores.miou * 100.0,
            scores.f1 * 100.0,
            scores.fpr * 100.0,
            scores.tpr * 100.0
        )?;
    }
    if let Some(said) = without_remission_said(&report) {
        writeln!(out, "{said}")?;
    }
    if let Some(said) = foreign_remission_said(&report, config) {
        writeln!(out, "{said}")?;
    }
    let (fit, poor_fit) = fit_said(&report.fit, &model);
    writeln!(out, "{fit}")?;
    if let Some(said) = poor_fit {
        writeln!(out, "notice: {said}")?;
    }
    if report.dropped_points > 0 {
        writeln!(
            out,
            "{} without a return (a NaN or infinite coordinate, or the sensor's origin) {} dropped",
            counted(report.dropped_points, "point"),
            if report.dropped_points == 1 {
                "was"
            } else {
                "were"
            }
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
            write_table(&mut out, geometric, true)?;
        }
        None if report.frames_with_images == 0 => {
            writeln!(out, "no camera images in these frames: geometry only")?;
        }
        None => writeln!(out, "the model has no hybrid part: geometry only")?,
    }
    if report.scored_frames > 0 {
        writeln!(
            out,
            "{}",
            training_note(training_frames, report.scored_frames)
        )?;
    }
    Ok(outcome(&selections))
}

/// Whether the scores are training scores: how many scored frames the model was
/// trained on, by scan content (None: the model does not record it).
fn training_note(training_frames: Option<usize>, scored: usize) -> String {
    let held_out = "`travmap crossval` gives held-out scores";
    match training_frames {
        None => format!(
            "note: this model does not record which scans it learnt from (trained from datasets, or by an older travmap); on its training frames these would be training scores. {held_out}."
        ),
        Some(0) => "none of the scored frames is a scan this model was trained on (compared by content): held-out scores".into(),
        Some(n) if n == scored => format!(
            "note: every scored frame is a scan this model was trained on (compared by content): these are training scores. {held_out}."
        ),
        Some(n) => format!(
            "note: {n} of the {scored} scored frames are scans this model was trained on (compared by content): those are training scores. {held_out}."
        ),
    }
}

/// The paper's geometry-only row (METHOD.md section 10), for reference.
const PAPER_GEOMETRY_ONLY: [f64; 7] = [85.8, 79.5, 87.9, 11.8, 89.4, 10.6, 88.2];

/// Percentages of a row; `n/a` without scores (no labelled frame).
fn score_row(s: Option<&Scores>) -> [Option<f64>; 7] {
    match s {
        Some(s) => [s.accuracy, s.miou, s.f1, s.fpr, s.tpr, s.fnr, s.tnr].map(|v| Some(100.0 * v)),
        None => [None; 7],
    }
}

/// `with_latency` false where the frames were not run one at a time (cross-validation).
pub(super) fn write_table(
    out: &mut impl Write,
    report: &EvaluationReport,
    with_latency: bool,
) -> Result<()> {
    writeln!(
        out,
        "{:<22} {:>6} {:>6} {:>6} {:>6} {:>6} {:>6} {:>6} {:>11}",
        "", "Acc", "mIoU", "F1", "FPR", "TPR", "FNR", "TNR", "latency"
    )?;
    let row = |name: &str, values: [Option<f64>; 7], latency: &str| {
        let cells: String = values
            .iter()
            .map(|v| match v {
                Some(v) => format!(" {v:>6.1}"),
                None => format!(" {:>6}", "n/a"),
            })
            .collect();
        format!("{name:<22}{cells} {latency:>11}")
    };
    let latency = if with_latency {
        format!("{:.2} ms", report.timings.latency_ms.median)
    } else {
        "n/a".into()
    };
    writeln!(
        out,
        "{}",
        row(
            "travmap (filtered)",
            score_row(report.scores.as_ref()),
            &latency
        )
    )?;
    writeln!(
        out,
        "{}",
        row(
            "travmap (SVM only)",
            score_row(report.unfiltered_scores.as_ref()),
            ""
        )
    )?;
    writeln!(
        out,
        "{}",
        row(
            "paper, geometry only",
            PAPER_GEOMETRY_ONLY.map(Some),
            "13 ms SVM"
        )
    )?;
    let c = &report.confusion;
    writeln!(
        out,
        "cells: TP {} TN {} FP {} FN {} unpredictable {} over {}",
        c.tp,
        c.tn,
        c.fp,
        c.r#fn,
        c.unknown,
        counted(report.scored_frames, "frame")
    )?;
    let t = &report.timings;
    if !with_latency {
        return Ok(());
    }
    writeln!(
        out,
        "median ms per frame: read {:.2}, integrate {:.2}, grid {:.2}, features {:.2}, appearance {:.2}, classify {:.2}, filter {:.2}; latency p95 {:.2}",
        t.read_ms.median,
        t.integrate_ms.median,
        t.grid_ms.median,
        t.features_ms.median,
        t.appearance_ms.median,
        t.classify_ms.median,
        t.filter_ms.median,
        t.latency_ms.p95
    )?;
    Ok(())
}
