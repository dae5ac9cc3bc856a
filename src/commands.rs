//! One function per subcommand of the `travmap` binary: each opens its inputs,
//! calls the library and prints a table (or JSON with `--json`). Errors get their
//! context here and are printed once by `main`.

use std::io::{IsTerminal, Write};
use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use indicatif::{ProgressBar, ProgressStyle};
use serde_json::json;

use std::collections::BTreeMap;

use crate::annotation::{self, AnnotationOptions};
use crate::benchmark::benchmark;
use crate::classifier::SvmModel;
use crate::classifier::training::TrainingSet;
use crate::classifier::training::train as train_model;
use crate::config::Config;
use crate::conversion::convert_kitti;
use crate::dataset;
use crate::evaluation::{
    CrossValidationReport, Evaluation, EvaluationReport, Selection, collect_training_set,
    cross_validate,
};
use crate::features::FEATURE_COUNT;
use crate::grid::CellClass;
use crate::metrics::Scores;
use crate::reading::mcap_drive::DriveOptions;
use crate::reading::{Source, parse_frame_range};
use crate::rendering;
use crate::writing::{Compression, write_atomically};

/// The drives a command reads and the frames of each.
#[derive(Clone)]
pub struct Inputs {
    /// KITTI sequence directories or MCAP files.
    pub sequences: Vec<PathBuf>,
    /// How to read MCAP drives.
    pub drive: DriveOptions,
    /// Skip frames whose input is unreadable instead of stopping.
    pub keep_going: bool,
    /// `A..B`, `A..=B`, `A..` or `N`; all frames when None.
    pub frames: Option<String>,
}

/// How a command ended: exit code 0, or 3 when it completed but skipped frames
/// (`--keep-going`), as the mcap CLI reports data loss.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Outcome {
    Complete,
    Skipped(usize),
}

/// Prints every skipped frame to stderr, once, and says how the command ended.
fn outcome(selections: &[Selection]) -> Outcome {
    let mut skipped = 0;
    for selection in selections {
        for skip in selection.source.skipped() {
            eprintln!(
                "skipped frame {} of {}: {}",
                skip.frame,
                selection.source.path().display(),
                skip.reason
            );
            skipped += 1;
        }
    }
    if skipped == 0 {
        Outcome::Complete
    } else {
        Outcome::Skipped(skipped)
    }
}

/// How a command reports.
#[derive(Clone, Copy)]
pub struct Output {
    pub json: bool,
    pub quiet: bool,
}

impl Output {
    /// A progress bar on a terminal, hidden otherwise or with `--quiet` / `--json`.
    fn progress(&self, length: u64, message: &str) -> ProgressBar {
        if self.quiet || self.json || !std::io::stderr().is_terminal() {
            return ProgressBar::hidden();
        }
        let bar = ProgressBar::new(length).with_message(message.to_string());
        bar.set_style(
            ProgressStyle::with_template("{msg:<24} [{bar:30}] {pos}/{len} {elapsed}")
                .expect("valid template")
                .progress_chars("=> "),
        );
        bar
    }
}

/// The effective configuration: defaults, then the file, then each `--set`.
pub fn load_config(file: Option<&Path>, assignments: &[String]) -> Result<Config> {
    let mut config = match file {
        Some(path) => Config::from_toml_file(path)?,
        None => Config::default(),
    };
    for assignment in assignments {
        config.set(assignment)?;
    }
    config.validate()?;
    Ok(config)
}

/// A model file, or the embedded default model, checked against `config`.
pub fn load_model(path: Option<&Path>, config: &Config) -> Result<(SvmModel, String)> {
    let (mut model, name) = match path {
        Some(path) => {
            let bytes = std::fs::read(path)
                .with_context(|| format!("cannot read model {}", path.display()))?;
            let name = path.display().to_string();
            (SvmModel::from_json(&bytes, &name)?, name)
        }
        None => (
            SvmModel::embedded_default()?,
            "embedded default model".into(),
        ),
    };
    model.check_compatible(config)?;
    if !config.classifier.use_reduced_set {
        model.reduced_set = None;
    }
    Ok((model, name))
}

/// Opens every input; `read_images` decodes camera images into the frames.
fn open_inputs(inputs: &Inputs, read_images: bool) -> Result<Vec<Selection>> {
    let frames = match &inputs.frames {
        Some(text) => parse_frame_range(text)?,
        None => 0..usize::MAX,
    };
    if inputs.sequences.is_empty() {
        bail!("no sequence directory given");
    }
    inputs
        .sequences
        .iter()
        .map(|path| {
            let mut source = Source::open(path, &inputs.drive)?;
            source.set_read_images(read_images);
            source.set_keep_going(inputs.keep_going);
            if source.frames_in(&frames).is_empty() {
                let all = source.frames();
                let has = match (all.first(), all.last()) {
                    (Some(first), Some(last)) => format!("frames {first}..={last}"),
                    _ => "no frames".into(),
                };
                bail!(
                    "{}: no scans in frames {}..{} (the input has {has})",
                    path.display(),
                    frames.start,
                    frames.end,
                );
            }
            Ok(Selection {
                source,
                frames: frames.clone(),
            })
        })
        .collect()
}

fn frame_count(selections: &[Selection]) -> u64 {
    selections
        .iter()
        .map(|s| s.source.frames_in(&s.frames).len() as u64)
        .sum()
}

fn model_json(model: &SvmModel, name: &str) -> serde_json::Value {
    json!({
        "name": name,
        "sha256": model.sha256_hex(),
        "support_vectors": model.support_vector_count(),
        "c": model.c,
        "gamma": model.gamma,
        "trained_on": model.training.sources,
    })
}

/// `travmap run`: the filtered grid of every frame.
pub fn run(
    inputs: &Inputs,
    config: &Config,
    model_path: Option<&Path>,
    ascii: bool,
    output: Output,
) -> Result<Outcome> {
    let (model, model_name) = load_model(model_path, config)?;
    let selections = open_inputs(inputs, config.appearance.enabled)?;
    let bar = output.progress(frame_count(&selections), "predicting");
    let mut stdout = std::io::stdout().lock();
    if output.json {
        writeln!(
            stdout,
            "{}",
            json!({"config": config, "model": model_json(&model, &model_name)})
        )?;
    } else if !output.quiet {
        writeln!(
            stdout,
            "model: {model_name} ({} support vectors)",
            model.support_vector_count()
        )?;
        writeln!(
            stdout,
            "{:>6} {:>10} {:>6} {:>11} {:>11} {:>9} {:>10}",
            "frame", "stamp_s", "cells", "predictable", "traversable", "non-trav", "latency_ms"
        )?;
    }
    let mut evaluation = Evaluation::default();
    for selection in &selections {
        selection.run::<anyhow::Error>(config, Some(&model), |result| {
            bar.inc(1);
            evaluation.add(&result);
            let grid = result.filtered.as_deref().unwrap_or(&[]);
            let count = |class: CellClass| grid.iter().filter(|c| **c == class).count();
            let (traversable, non_traversable) = (
                count(CellClass::Traversable),
                count(CellClass::NonTraversable),
            );
            if output.json {
                let cells: Vec<i8> = grid
                    .iter()
                    .map(|c| match c {
                        CellClass::Unknown => -1,
                        CellClass::Traversable => 0,
                        CellClass::NonTraversable => 100,
                    })
                    .collect();
                let line = json!({
                    "input": selection.source.path(),
                    "frame": result.index,
                    "stamp_ns": result.stamp_ns,
                    "cell_size_m": result.layout.cell_size_m,
                    "cells_per_side": result.layout.cells_per_side,
                    "min_corner_in_world": result.layout.min_corner_in_world(),
                    "cells": cells,
                    "timings_ms": result.timings,
                    "dropped_points": result.dropped_points,
                });
                writeln!(stdout, "{line}")?;
            } else if !output.quiet {
                writeln!(
                    stdout,
                    "{:>6} {:>10.3} {:>6} {:>11} {:>11} {:>9} {:>10.2}",
                    result.index,
                    result.stamp_ns as f64 * 1e-9,
                    grid.len(),
                    traversable + non_traversable,
                    traversable,
                    non_traversable,
                    result.timings.latency_ms
                )?;
                if ascii {
                    write_ascii_grid(&mut stdout, grid, result.layout.cells_per_side)?;
                }
            }
            Ok(())
        })?;
    }
    bar.finish_and_clear();
    if !output.json && !output.quiet {
        let latency = evaluation.report().timings_ms.latency;
        writeln!(
            stdout,
            "median latency {:.2} ms per frame (p95 {:.2} ms)",
            latency.median, latency.p95
        )?;
    }
    Ok(outcome(&selections))
}

/// Rows from north (max y) down, so the picture reads like a map with x to the right.
fn write_ascii_grid(out: &mut impl Write, grid: &[CellClass], cells_per_side: usize) -> Result<()> {
    for row in grid.chunks(cells_per_side).rev() {
        let line: String = row.iter().map(|c| c.symbol()).collect();
        writeln!(out, "  |{line}|")?;
    }
    Ok(())
}

/// The paper's geometry-only row (METHOD.md section 10), for reference.
const PAPER_GEOMETRY_ONLY: [f64; 7] = [85.8, 79.5, 87.9, 11.8, 89.4, 10.6, 88.2];

fn score_row(s: &Scores) -> [f64; 7] {
    [s.accuracy, s.miou, s.f1, s.fpr, s.tpr, s.fnr, s.tnr].map(|v| 100.0 * v)
}

/// `with_latency` false where the frames were not run one at a time (cross-validation).
fn write_table(out: &mut impl Write, report: &EvaluationReport, with_latency: bool) -> Result<()> {
    writeln!(
        out,
        "{:<22} {:>6} {:>6} {:>6} {:>6} {:>6} {:>6} {:>6} {:>11}",
        "", "Acc", "mIoU", "F1", "FPR", "TPR", "FNR", "TNR", "latency"
    )?;
    let row = |name: &str, values: [f64; 7], latency: &str| {
        let cells: String = values.iter().map(|v| format!(" {v:>6.1}")).collect();
        format!("{name:<22}{cells} {latency:>11}")
    };
    let latency = if with_latency {
        format!("{:.2} ms", report.timings_ms.latency.median)
    } else {
        "n/a".into()
    };
    writeln!(
        out,
        "{}",
        row("travmap (filtered)", score_row(&report.scores), &latency)
    )?;
    writeln!(
        out,
        "{}",
        row(
            "travmap (SVM only)",
            score_row(&report.unfiltered_scores),
            ""
        )
    )?;
    writeln!(
        out,
        "{}",
        row("paper, geometry only", PAPER_GEOMETRY_ONLY, "13 ms SVM")
    )?;
    let c = &report.confusion;
    writeln!(
        out,
        "cells: TP {} TN {} FP {} FN {} unpredictable {} over {} frames",
        c.tp, c.tn, c.fp, c.r#fn, c.unknown, report.frames
    )?;
    let t = &report.timings_ms;
    if !with_latency {
        return Ok(());
    }
    writeln!(
        out,
        "median ms per frame: read {:.2}, integrate {:.2}, grid {:.2}, features {:.2}, appearance {:.2}, classify {:.2}, filter {:.2}; latency p95 {:.2}",
        t.read.median,
        t.integrate.median,
        t.grid.median,
        t.features.median,
        t.appearance.median,
        t.classify.median,
        t.filter.median,
        t.latency.p95
    )?;
    Ok(())
}

/// `travmap eval`: the paper's table for the selected frames.
pub fn eval(
    inputs: &Inputs,
    config: &Config,
    model_path: Option<&Path>,
    output: Output,
) -> Result<Outcome> {
    let (model, model_name) = load_model(model_path, config)?;
    let selections = open_inputs(inputs, config.appearance.enabled)?;
    let evaluate = |model: &SvmModel, message: &str| -> Result<EvaluationReport> {
        let bar = output.progress(frame_count(&selections), message);
        let mut evaluation = Evaluation::default();
        for selection in &selections {
            selection.run::<anyhow::Error>(config, Some(model), |result| {
                bar.inc(1);
                evaluation.add(&result);
                Ok(())
            })?;
        }
        bar.finish_and_clear();
        Ok(evaluation.report())
    };
    let report = evaluate(&model, "evaluating")?;
    // The ablation of the paper: the same frames without appearance features.
    let geometry_only = match &model.hybrid {
        Some(_) if report.frames_with_images > 0 => {
            let mut geometric = model.clone();
            geometric.hybrid = None;
            Some(evaluate(&geometric, "geometry only")?)
        }
        _ => None,
    };
    let sources: Vec<String> = selections.iter().map(Selection::describe).collect();
    if output.json {
        let doc = json!({
            "config": config,
            "model": model_json(&model, &model_name),
            "inputs": sources,
            "report": report,
            "geometry_only_report": geometry_only,
        });
        println!("{}", serde_json::to_string_pretty(&doc)?);
        return Ok(outcome(&selections));
    }
    let mut out = std::io::stdout().lock();
    writeln!(out, "inputs: {}", sources.join("; "))?;
    let hybrid = match &model.hybrid {
        Some(h) => format!(
            "a hybrid model with {} support vectors for cells a camera saw",
            h.support_vector_count()
        ),
        None => "no hybrid model".into(),
    };
    writeln!(
        out,
        "model: {model_name} (sha256 {}, {} support vectors, C {}, gamma {}; {hybrid}), trained on {}",
        &model.sha256_hex()[..12],
        model.support_vector_count(),
        model.c,
        model.gamma,
        model.training.sources.join("; ")
    )?;
    if report.frames == 0 {
        writeln!(
            out,
            "no frame has ground truth (labels/ for every scan of its window): nothing to score"
        )?;
    }
    write_table(&mut out, &report, true)?;
    if report.dropped_points > 0 {
        writeln!(
            out,
            "{} points with a non-finite coordinate were dropped",
            report.dropped_points
        )?;
    }
    match &geometry_only {
        Some(geometric) => {
            writeln!(
                out,
                "ablation: the rows above use appearance for the {} cells of {} frames that a camera saw; without it:",
                report.cells_with_appearance, report.frames_with_images
            )?;
            write_table(&mut out, geometric, true)?;
        }
        None if report.frames_with_images == 0 => {
            writeln!(out, "no camera images in these frames: geometry only")?;
        }
        None => writeln!(out, "the model has no hybrid part: geometry only")?,
    }
    if model_path.is_none() {
        writeln!(
            out,
            "note: the embedded model was trained on the shipped labelled frames; scores on those frames are \
             training scores. `travmap crossval` gives the spatially held-out accuracy."
        )?;
    }
    Ok(outcome(&selections))
}

/// `travmap dataset`: one Parquet row per predictable cell per frame, on the
/// training grid (`training.grid_size_m`), the cells `train` learns from.
pub fn dataset(
    inputs: &Inputs,
    config: &Config,
    model_path: Option<&Path>,
    output_path: &Path,
    output: Output,
) -> Result<Outcome> {
    let selections = open_inputs(inputs, config.appearance.enabled)?;
    let model = match model_path {
        Some(path) => Some(load_model(Some(path), config)?.0),
        None => None,
    };
    let mut grid_config = config.clone();
    grid_config.grid.size_m = config.training.grid_size_m;
    let started = std::time::Instant::now();
    let bar = output.progress(frame_count(&selections), "extracting cells");
    let mut writer = dataset::DatasetWriter::create(output_path, config)?;
    for selection in &selections {
        let source = selection.source.path().display().to_string();
        selection.run::<anyhow::Error>(&grid_config, model.as_ref(), |result| {
            writer.push_frame(&source, &result)?;
            bar.inc(1);
            Ok(())
        })?;
    }
    let summary = writer.finish()?;
    bar.finish_and_clear();
    let seconds = started.elapsed().as_secs_f64();
    if output.json {
        let doc = json!({"output": output_path, "summary": summary, "seconds": seconds, "cells_per_s": summary.rows as f64 / seconds});
        println!("{}", serde_json::to_string_pretty(&doc)?);
    } else if !output.quiet {
        println!(
            "wrote {}: {} cells from {} frames ({} labelled, {} with appearance), {:.0} cells/s",
            output_path.display(),
            summary.rows,
            summary.frames,
            summary.labelled_rows,
            summary.rows_with_appearance,
            summary.rows as f64 / seconds
        );
    }
    Ok(outcome(&selections))
}

/// `travmap train`: grid search, final fit, model file.
pub fn train(
    inputs: &Inputs,
    config: &Config,
    model_path: &Path,
    output: Output,
) -> Result<Outcome> {
    // Cell datasets (`travmap dataset`) join the cells of the drives given.
    let (datasets, drives): (Vec<PathBuf>, Vec<PathBuf>) = inputs
        .sequences
        .iter()
        .cloned()
        .partition(|path| path.extension().is_some_and(|e| e == "parquet"));
    let selections = if drives.is_empty() {
        Vec::new()
    } else {
        let drives = Inputs {
            sequences: drives,
            ..inputs.clone()
        };
        open_inputs(&drives, config.appearance.enabled)?
    };
    let mut set = if selections.is_empty() {
        TrainingSet {
            dimension: FEATURE_COUNT,
            ..Default::default()
        }
    } else {
        let bar = output.progress(frame_count(&selections), "collecting cells");
        let set = collect_training_set(&selections, config, &mut || bar.inc(1))?;
        bar.finish_and_clear();
        set
    };
    for path in &datasets {
        let rows = dataset::read_training_rows(path, config, &mut set)?;
        set.sources
            .push(format!("{} ({rows} labelled cells)", path.display()));
    }
    if set.is_empty() {
        bail!(
            "no labelled cells in {}",
            datasets
                .iter()
                .map(|p| p.display().to_string())
                .collect::<Vec<_>>()
                .join(", ")
        );
    }
    let searches =
        config.training.c_values.len() * config.training.gamma_values.len() * config.training.folds
            + 1;
    let bar = output.progress(searches as u64, "grid search + final fit");
    let model = train_model(&set, config, &|done, total| {
        bar.set_length(total as u64);
        bar.set_position(done as u64);
    })?;
    bar.finish_and_clear();
    write_atomically(model_path, &model.to_json())?;
    let best = model
        .training
        .search
        .iter()
        .find(|r| r.c == model.c && r.gamma == model.gamma)
        .copied();
    if output.json {
        let doc = json!({
            "model": model_path,
            "sha256": model.sha256_hex(),
            "config": config,
            "cells": set.len(),
            "training": model.training,
            "support_vectors": model.support_vector_count(),
            "c": model.c,
            "gamma": model.gamma,
            "hybrid": model.hybrid.as_ref().map(|h| json!({
                "samples": h.training.samples,
                "support_vectors": h.support_vector_count(),
                "c": h.c,
                "gamma": h.gamma,
                "search": h.training.search,
            })),
        });
        println!("{}", serde_json::to_string_pretty(&doc)?);
    } else if !output.quiet {
        println!(
            "trained on {} cells ({} traversable) from {}",
            model.training.samples,
            model.training.traversable_samples,
            model.training.sources.join("; ")
        );
        if model.training.samples < set.len() {
            println!(
                "  a seeded random {} of the {} cells (training.max_fit_samples)",
                model.training.samples,
                set.len()
            );
        }
        println!(
            "grid search (spatially-blocked {}-fold CV accuracy, cells before filtering):",
            config.training.folds
        );
        for r in &model.training.search {
            println!(
                "  C {:>8} gamma {:>8}  {:.1} %",
                r.c,
                r.gamma,
                100.0 * r.accuracy
            );
        }
        println!(
            "chosen C {} gamma {} (CV accuracy {:.1} %): {} support vectors, {} solver iterations, {:.1} s",
            model.c,
            model.gamma,
            100.0 * best.map_or(0.0, |b| b.accuracy),
            model.support_vector_count(),
            model.training.solver_iterations,
            model.training.seconds
        );
        match &model.hybrid {
            Some(h) => println!(
                "hybrid model (geometry + appearance) on the {} cells a camera saw: C {} gamma {}, {} support vectors",
                h.training.samples,
                h.c,
                h.gamma,
                h.support_vector_count()
            ),
            None => println!("no hybrid model: no labelled cell was seen by a camera"),
        }
        println!("wrote {}", model_path.display());
    }
    Ok(outcome(&selections))
}

/// `travmap crossval`: the spatially-blocked held-out evaluation.
pub fn crossval(inputs: &Inputs, config: &Config, output: Output) -> Result<Outcome> {
    let selections = open_inputs(inputs, config.appearance.enabled)?;
    let bar = output.progress(config.training.folds as u64, "cross-validating");
    let report: CrossValidationReport = cross_validate(&selections, config, &|message| {
        bar.set_message(message.to_string());
        bar.inc(1);
    })?;
    bar.finish_and_clear();
    let sources: Vec<String> = selections.iter().map(Selection::describe).collect();
    if output.json {
        let doc = json!({"config": config, "inputs": sources, "report": report});
        println!("{}", serde_json::to_string_pretty(&doc)?);
        return Ok(outcome(&selections));
    }
    let mut out = std::io::stdout().lock();
    writeln!(out, "inputs: {}", sources.join("; "))?;
    writeln!(
        out,
        "spatially-blocked {}-fold cross-validation, {} m world blocks; each fold's model has its own grid search",
        config.training.folds, report.block_size_m
    )?;
    for f in &report.folds {
        writeln!(
            out,
            "  fold {}: trained on {} cells (test blocks hold {}), C {} gamma {}, {} support vectors, {:.1} s",
            f.fold,
            f.training_cells,
            f.test_cells,
            f.c,
            f.gamma,
            f.support_vectors,
            f.training_seconds
        )?;
    }
    write_table(&mut out, &report.evaluation, false)?;
    Ok(outcome(&selections))
}

/// `travmap config`: the effective configuration as TOML (or JSON).
pub fn print_config(config: &Config, output: Output) -> Result<()> {
    if output.json {
        println!("{}", serde_json::to_string_pretty(config)?);
    } else {
        print!("{}", toml::to_string(config)?);
    }
    Ok(())
}

/// `travmap bench`: the per-stage table and throughput.
pub fn bench(
    inputs: &Inputs,
    config: &Config,
    model_path: Option<&Path>,
    repeats: usize,
    output: Output,
) -> Result<Outcome> {
    let (model, model_name) = load_model(model_path, config)?;
    let selections = open_inputs(inputs, config.appearance.enabled)?;
    let [selection] = selections.as_slice() else {
        bail!(
            "bench takes one sequence directory, got {}",
            selections.len()
        );
    };
    let report = benchmark(
        &selection.source,
        &selection.frames,
        config,
        &model,
        repeats,
    )?;
    if output.json {
        let doc = json!({"config": config, "model": model_json(&model, &model_name), "input": selection.describe(), "report": report});
        println!("{}", serde_json::to_string_pretty(&doc)?);
        return Ok(outcome(&selections));
    }
    let mut out = std::io::stdout().lock();
    writeln!(out, "input: {}", selection.describe())?;
    writeln!(
        out,
        "{} timed frames x {} repeats; n = {} scans of {:.0} points, {} x {} grid of {} m ({:.0} predictable cells, {:.0} points in grid); {model_name}, {} support vectors",
        report.timed_frames,
        report.repeats,
        config.integration.scans,
        report.mean_points_per_scan,
        config.grid.cells_per_side(),
        config.grid.cells_per_side(),
        config.grid.cell_size_m,
        report.predictable_cells,
        report.points_in_grid,
        report.support_vectors
    )?;
    writeln!(
        out,
        "{:<34} {:>9} {:>9}",
        "stage (1 thread, frame by frame)", "median ms", "p95 ms"
    )?;
    let t = &report.stages_ms;
    for (name, spread) in [
        ("read + image decode (not in latency)", t.read),
        ("integrate", t.integrate),
        ("grid", t.grid),
        ("geometric features", t.features),
        ("appearance: projection + voting", t.appearance),
        ("classify", t.classify),
        ("filter", t.filter),
        ("latency: scan in to filtered grid", t.latency),
    ] {
        writeln!(out, "{name:<34} {:>9.3} {:>9.3}", spread.median, spread.p95)?;
    }
    writeln!(
        out,
        "{:<34} {:>9}",
        "write", "not in this table: see `annotate` frames/s"
    )?;
    writeln!(
        out,
        "throughput (whole selection, rayon across frames): {:.1} frames/s on 1 thread, {:.1} frames/s on {} threads ({:.2}x)",
        report.one_thread.frames_per_second,
        report.all_cores.frames_per_second,
        report.all_cores.threads,
        report.speedup
    )?;
    Ok(outcome(&selections))
}

/// `travmap convert`: a KITTI sequence to a ROS 2 MCAP.
pub fn convert(
    inputs: &Inputs,
    output_path: &Path,
    compression: Compression,
    start_time_s: f64,
    output: Output,
) -> Result<Outcome> {
    if !(start_time_s.is_finite() && start_time_s >= 0.0) {
        bail!("--start-time must be seconds >= 0, got {start_time_s}");
    }
    let selections = open_inputs(inputs, false)?;
    let [
        Selection {
            source: Source::Kitti(sequence),
            frames,
        },
    ] = selections.as_slice()
    else {
        bail!("convert takes one KITTI sequence directory");
    };
    let bar = output.progress(frame_count(&selections), "converting");
    let started = std::time::Instant::now();
    let start_ns = (start_time_s * 1e9).round() as u64;
    let summary = convert_kitti(
        sequence,
        frames,
        output_path,
        compression,
        start_ns,
        &|| bar.inc(1),
    )?;
    bar.finish_and_clear();
    let seconds = started.elapsed().as_secs_f64();
    if output.json {
        let doc = json!({"output": output_path, "compression": compression, "summary": summary, "seconds": seconds});
        println!("{}", serde_json::to_string_pretty(&doc)?);
    } else if !output.quiet {
        println!(
            "wrote {} ({} frames, {} with labels, {} images, {:.1} MB, {:.1} frames/s)",
            output_path.display(),
            summary.frames,
            summary.labelled_frames,
            summary.images,
            summary.output_bytes as f64 / 1e6,
            summary.frames as f64 / seconds
        );
        if summary.dropped_points > 0 {
            eprintln!(
                "{} points with a non-finite coordinate were left out",
                summary.dropped_points
            );
        }
    }
    Ok(outcome(&selections))
}

/// `travmap annotate`: the annotated MCAP.
pub fn annotate(
    inputs: &Inputs,
    config: &Config,
    model_path: Option<&Path>,
    output_path: &Path,
    options: &AnnotationOptions,
    output: Output,
) -> Result<Outcome> {
    let (model, model_name) = load_model(model_path, config)?;
    let selections = open_inputs(inputs, config.appearance.enabled)?;
    let [selection] = selections.as_slice() else {
        bail!(
            "annotate takes one input (a KITTI sequence directory or an MCAP file), got {}",
            selections.len()
        );
    };
    let metadata = BTreeMap::from([
        (
            "travmap_version".to_string(),
            env!("CARGO_PKG_VERSION").to_string(),
        ),
        ("config".to_string(), serde_json::to_string(config)?),
        ("model".to_string(), model_name.clone()),
        ("model_sha256".to_string(), model.sha256_hex()),
        ("input".to_string(), selection.describe()),
    ]);
    let bar = output.progress(frame_count(&selections), "annotating");
    let started = std::time::Instant::now();
    let summary = annotation::annotate(
        selection,
        config,
        &model,
        metadata,
        output_path,
        options,
        &|| bar.inc(1),
    )?;
    bar.finish_and_clear();
    let seconds = started.elapsed().as_secs_f64();
    if output.json {
        let doc = json!({"output": output_path, "config": config, "model": model_json(&model, &model_name), "summary": summary, "seconds": seconds});
        println!("{}", serde_json::to_string_pretty(&doc)?);
    } else if !output.quiet {
        println!(
            "wrote {} ({} frames, {} messages copied through, {:.1} MB, {:.1} frames/s)",
            output_path.display(),
            summary.frames,
            summary.passthrough_messages,
            summary.output_bytes as f64 / 1e6,
            summary.frames as f64 / seconds
        );
        if summary.evaluation.frames > 0 {
            let s = summary.evaluation.scores;
            println!(
                "{} frames with ground truth: Acc {:.1} mIoU {:.1} F1 {:.1} (filtered)",
                summary.evaluation.frames,
                100.0 * s.accuracy,
                100.0 * s.miou,
                100.0 * s.f1
            );
        }
    }
    Ok(outcome(&selections))
}

/// `travmap render`: ground truth, prediction and errors of frames as PNG pictures,
/// one file (`all` false: the selected frame) or one per frame into a directory.
pub fn render(
    inputs: &Inputs,
    config: &Config,
    model_path: Option<&Path>,
    output_path: &Path,
    all: bool,
    cell_px: u32,
    output: Output,
) -> Result<Outcome> {
    if !(1..=64).contains(&cell_px) {
        bail!("--cell-pixels must be in 1..=64, got {cell_px}");
    }
    let (model, _) = load_model(model_path, config)?;
    let selections = open_inputs(inputs, config.appearance.enabled)?;
    let [selection] = selections.as_slice() else {
        bail!("render takes one input, got {}", selections.len());
    };
    if all {
        std::fs::create_dir_all(output_path)
            .with_context(|| format!("cannot create {}", output_path.display()))?;
    }
    let bar = output.progress(frame_count(&selections), "rendering");
    let mut written = Vec::new();
    selection.run::<anyhow::Error>(config, Some(&model), |result| {
        let path = if all {
            output_path.join(format!("{:06}.png", result.index))
        } else {
            output_path.to_path_buf()
        };
        write_atomically(
            &path,
            &rendering::encode_png(&rendering::render(&result, cell_px)),
        )?;
        written.push(path);
        bar.inc(1);
        Ok(())
    })?;
    bar.finish_and_clear();
    if written.is_empty() {
        bail!("no frame was rendered");
    }
    if output.json {
        println!(
            "{}",
            serde_json::to_string_pretty(&json!({"pictures": written}))?
        );
    } else if !output.quiet {
        println!(
            "wrote {} picture(s): ground truth | prediction | errors (orange false positive, blue false negative)",
            written.len()
        );
        for path in &written {
            println!("  {}", path.display());
        }
    }
    Ok(outcome(&selections))
}
