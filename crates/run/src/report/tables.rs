//! The text a person reads: the paper's score table, what a model is and learnt
//! from, whether scores are training scores, what a training did, and the
//! benchmark's stage table.

use std::fmt::Write;

use travmap_core::Config;
use travmap_method::classifier::{AdaptationSummary, SvmModel};

use crate::report::json::setting_word;
use crate::scoring::benchmark::BenchmarkReport;
use crate::scoring::evaluation::EvaluationReport;
use crate::scoring::metrics::{Confusion, Scores};
use crate::scoring::remarks::counted;

/// The paper's geometry-only row (METHOD.md section 10), for reference.
const PAPER_GEOMETRY_ONLY: [f64; 7] = [85.8, 79.5, 87.9, 11.8, 89.4, 10.6, 88.2];

/// Percentages of a row; `n/a` without scores (no labelled frame).
fn score_row(s: Option<&Scores>) -> [Option<f64>; 7] {
    match s {
        Some(s) => [s.accuracy, s.miou, s.f1, s.fpr, s.tpr, s.fnr, s.tnr].map(|v| Some(100.0 * v)),
        None => [None; 7],
    }
}

/// The paper's table of `report`: filtered and SVM-only rows beside the paper's, the
/// cells counted, and the stages' times; `with_latency` false where the frames were
/// not run one at a time (cross-validation).
pub fn score_table(report: &EvaluationReport, with_latency: bool) -> String {
    let mut out = String::new();
    let row = |out: &mut String, name: &str, values: [Option<f64>; 7], latency: &str| {
        let cells: String = values
            .iter()
            .map(|v| match v {
                Some(v) => format!(" {v:>6.1}"),
                None => format!(" {:>6}", "n/a"),
            })
            .collect();
        let _ = writeln!(out, "{name:<22}{cells} {latency:>11}");
    };
    let _ = writeln!(
        out,
        "{:<22} {:>6} {:>6} {:>6} {:>6} {:>6} {:>6} {:>6} {:>11}",
        "", "Acc", "mIoU", "F1", "FPR", "TPR", "FNR", "TNR", "latency"
    );
    let latency = match with_latency {
        true => format!("{:.2} ms", report.timings.latency_ms.median),
        false => "n/a".into(),
    };
    let filtered = score_row(report.scores.as_ref());
    row(&mut out, "travmap (filtered)", filtered, &latency);
    let unfiltered = score_row(report.unfiltered_scores.as_ref());
    row(&mut out, "travmap (SVM only)", unfiltered, "");
    let paper = PAPER_GEOMETRY_ONLY.map(Some);
    row(&mut out, "paper, geometry only", paper, "13 ms SVM");
    let c = &report.confusion;
    let _ = writeln!(
        out,
        "cells: TP {} TN {} FP {} FN {} unpredictable {} over {}",
        c.tp,
        c.tn,
        c.fp,
        c.r#fn,
        c.unknown,
        counted(report.scored_frames, "frame")
    );
    if with_latency {
        let t = &report.timings;
        let _ = writeln!(
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
        );
    }
    out
}

/// The drive map's scores, each world cell once; None when no cell was scored.
pub fn fused_line(fused: &Confusion) -> Option<String> {
    let scores = fused.scores_if_predicted()?;
    Some(format!(
        "fused drive map ({} world cells, each once): Acc {:.1} mIoU {:.1} F1 {:.1} FPR {:.1} TPR {:.1}",
        fused.predicted(),
        scores.accuracy * 100.0,
        scores.miou * 100.0,
        scores.f1 * 100.0,
        scores.fpr * 100.0,
        scores.tpr * 100.0
    ))
}

/// What a model is and what it learnt from, in a line.
pub fn model_line(model: &SvmModel, name: &str) -> String {
    let hybrid = match &model.hybrid {
        Some(h) => format!(
            "a hybrid model with {} support vectors for cells a camera saw",
            h.support_vector_count()
        ),
        None => "no hybrid model".into(),
    };
    let kept = |a: &AdaptationSummary| a.check.as_ref().is_some_and(|c| !c.adapted);
    let sources = model.training.sources.join("; ");
    let learnt = match &model.training.adaptation {
        Some(adaptation) if kept(adaptation) => format!(
            "{} as it was (adaptation's check kept it), trained on {sources}",
            adaptation.prior
        ),
        Some(adaptation) => format!(
            "adapted to {sources} (no labels read) from {}",
            adaptation.prior
        ),
        None => format!("trained on {sources}"),
    };
    format!(
        "model: {name} (sha256 {}, {} support vectors, C {}, gamma {}; {hybrid}), {learnt}",
        &model.sha256_hex()[..12],
        model.support_vector_count(),
        model.c,
        model.gamma,
    )
}

/// Whether the scores are training scores: how many of the `scored` frames the
/// model was trained on, by scan content (None: the model does not record it).
pub fn training_note(training_frames: Option<usize>, scored: usize) -> String {
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

/// The benchmark's table: what was timed, each stage's median and p95 on one thread,
/// the floor, and the throughput on one thread and on all cores.
pub fn stage_table(report: &BenchmarkReport, config: &Config, model_name: &str) -> String {
    let mut out = String::new();
    let side = config.grid.cells_per_side();
    let _ = writeln!(
        out,
        "{} timed frames x {} repeats; n = {} scans of {:.0} points, {side} x {side} grid of {} m ({:.0} predictable cells, {:.0} points in grid); {model_name}, {} support vectors",
        report.timed_frames,
        report.repeats,
        config.integration.scans,
        report.mean_points_per_scan,
        config.grid.cell_size_m,
        report.predictable_cells,
        report.points_in_grid,
        report.support_vectors
    );
    let _ = writeln!(
        out,
        "{:<34} {:>9} {:>9}",
        "stage (1 thread, frame by frame)", "median ms", "p95 ms"
    );
    let t = &report.timings;
    for (name, spread) in [
        ("read + image decode (not in latency)", t.read_ms),
        (
            "registration (--poses registration)",
            report.registration_ms,
        ),
        ("integrate", t.integrate_ms),
        ("grid", t.grid_ms),
        ("geometric features", t.features_ms),
        ("appearance: projection + voting", t.appearance_ms),
        ("classify", t.classify_ms),
        ("filter", t.filter_ms),
        ("latency: scan in to filtered grid", t.latency_ms),
    ] {
        let _ = writeln!(out, "{name:<34} {:>9.3} {:>9.3}", spread.median, spread.p95);
    }
    let _ = writeln!(
        out,
        "{:<34} {:>9.3} {:>9.3}   latency = {:.1}x the floor",
        "floor: move + count in cells",
        report.floor_ms.median,
        report.floor_ms.p95,
        report.latency_over_floor
    );
    if report.registration_lost > 0 {
        let _ = writeln!(
            out,
            "  ({} scans over the repeats did not register; the map started again from each)",
            report.registration_lost
        );
    }
    let _ = writeln!(
        out,
        "{:<34} {:>9}",
        "write", "not in this table: see `bench --tools`"
    );
    let _ = writeln!(
        out,
        "throughput (whole selection, rayon across frames): {:.1} frames/s on 1 thread, {:.1} frames/s on {} threads ({:.2}x)",
        report.one_thread.frames_per_second,
        report.all_cores.frames_per_second,
        report.all_cores.threads,
        report.speedup
    );
    out
}

/// What a training did: the cells it learnt from (`cells` collected, a sample of
/// them fitted), the grid search's rows, the chosen fit and the hybrid model.
pub fn training_text(model: &SvmModel, cells: usize, config: &Config) -> String {
    let mut out = String::new();
    let training = &model.training;
    let _ = writeln!(
        out,
        "trained on {} cells ({} traversable) from {}",
        training.samples,
        training.traversable_samples,
        training.sources.join("; ")
    );
    if training.samples < cells {
        let _ = writeln!(
            out,
            "  a seeded random {} of the {cells} cells (training.max_fit_samples)",
            training.samples
        );
    }
    // C and gamma given (a prior's, adaptation's): no search to report.
    if training.search.is_empty() {
        let _ = writeln!(
            out,
            "C {} gamma {} as given (no grid search): {} support vectors, {} solver iterations, {:.1} s",
            model.c,
            model.gamma,
            model.support_vector_count(),
            training.solver_iterations,
            training.seconds
        );
    } else {
        let _ = writeln!(
            out,
            "grid search (spatially-blocked {}-fold CV, cells before filtering; by {} (training.criterion), class weights {} (training.class_weights)):",
            config.training.folds,
            setting_word(&config.training.criterion),
            setting_word(&config.training.class_weights)
        );
    }
    for r in &training.search {
        let _ = writeln!(
            out,
            "  C {:>8} gamma {:>8}  accuracy {:.1} %  mIoU {:.1} %",
            r.c,
            r.gamma,
            100.0 * r.accuracy,
            100.0 * r.miou
        );
    }
    let best = (training.search.iter()).find(|r| r.c == model.c && r.gamma == model.gamma);
    let (accuracy, miou) = best.map_or((0.0, 0.0), |b| (b.accuracy, b.miou));
    let _ = (!training.search.is_empty()).then(|| writeln!(
        out,
        "chosen C {} gamma {} (CV accuracy {:.1} %, mIoU {:.1} %): {} support vectors, {} solver iterations, {:.1} s",
        model.c,
        model.gamma,
        100.0 * accuracy,
        100.0 * miou,
        model.support_vector_count(),
        training.solver_iterations,
        training.seconds
    ));
    let _ = match &model.hybrid {
        Some(h) => writeln!(
            out,
            "hybrid model (geometry + appearance) on the {} cells a camera saw: C {} gamma {}, {} support vectors",
            h.training.samples,
            h.c,
            h.gamma,
            h.support_vector_count()
        ),
        None => writeln!(
            out,
            "no hybrid model: no labelled cell was seen by a camera"
        ),
    };
    out
}
