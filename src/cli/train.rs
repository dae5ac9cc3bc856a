//! `travmap train`: grid search over C and gamma with spatially-blocked CV, a final
//! fit, and the model file; from drives and from Parquet cell datasets.

use std::path::PathBuf;

use anyhow::{Result, bail};
use clap::Args;
use serde_json::json;
use travmap_outputs::atomic::write_atomically;
use travmap_outputs::dataset::part_files;
use travmap_outputs::dataset::reading::{Labels, read_training_rows};
use travmap_run::Fingerprints;
use travmap_run::report::tables::training_text;
use travmap_training::crossval::collect_training_set;
use travmap_training::{TrainingSet, train as train_model};

use super::{
    Inputs, Outcome, check_output, frame_count, input_json, model_json, note_extension, outcome,
    path_text, print_json_summary,
};

/// Train the SVM (grid search over C and gamma, spatially-blocked CV).
#[derive(Args)]
#[command(
    after_long_help = "Examples (SEQ: a KITTI sequence folder, e.g. ../shared/data/semantickitti-00/sequences/00):\n  travmap train SEQ -o model.json\n  travmap train cells.parquet more_cells/ -o model.json\n  travmap train SEQ -o model.json --set 'training.c_values=[10]'"
)]
pub struct TrainArgs {
    #[command(flatten)]
    inputs: Inputs,
    /// Where to write the model (JSON).
    #[arg(short, long)]
    output: PathBuf,
    /// Which labels to learn: `ground-truth` (annotations, default) or `pseudo` (the
    /// self-labels of Parquet datasets' `pseudo_label` column: unlabelled fleet logs as
    /// training sets).
    #[arg(long, value_enum, default_value_t = LabelArg::GroundTruth)]
    labels: LabelArg,
}

/// `--labels`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
enum LabelArg {
    GroundTruth,
    Pseudo,
}

pub fn train(args: TrainArgs) -> Result<Outcome> {
    let config = &args.inputs.settings.load()?;
    let output = args.inputs.output;
    let model_path = args.output.as_path();
    check_output(model_path, &args.inputs.files(None))?;
    note_extension(model_path, "json", "a travmap model (JSON)");
    // Cell datasets (`travmap dataset`: a file, or a folder of part files) join the
    // cells of the drives given.
    let is_dataset = |path: &PathBuf| {
        path.extension().is_some_and(|e| e == "parquet")
            || (path.is_dir() && part_files(path).is_ok())
    };
    let (datasets, drives): (Vec<PathBuf>, Vec<PathBuf>) =
        args.inputs.sequences.iter().cloned().partition(is_dataset);
    if args.labels == LabelArg::Pseudo && !drives.is_empty() {
        bail!(
            "--labels pseudo learns from Parquet datasets (`travmap dataset` writes their pseudo_label column); {} is a drive: extract it with `travmap dataset` first, or adapt to it with `travmap adapt`",
            drives[0].display()
        );
    }
    let labels = match args.labels {
        LabelArg::GroundTruth => Labels::GroundTruth,
        LabelArg::Pseudo => Labels::Pseudo,
    };
    let mut selections = if drives.is_empty() {
        Vec::new()
    } else {
        let options = args.inputs.source_options(config)?;
        args.inputs
            .open_paths(&drives, &options, config, config.appearance.enabled)?
    };
    // The model records which scans it learnt from, so `eval` can tell them apart.
    for selection in &mut selections {
        selection.fingerprint_scans = Fingerprints::Labelled;
    }
    let mut set = if selections.is_empty() {
        TrainingSet::for_features(config)
    } else {
        let bar = output.progress(frame_count(&selections), "collecting cells");
        let set = collect_training_set(&selections, config, &mut || bar.inc(1))?;
        bar.finish();
        set
    };
    let mut inputs: Vec<serde_json::Value> = selections.iter().map(input_json).collect();
    for path in &datasets {
        let rows = read_training_rows(path, config, &mut set, labels)?;
        inputs.push(json!({"path": path_text(path), "frames": null, "cells": rows}));
        let kind = match labels {
            Labels::GroundTruth => "labelled",
            Labels::Pseudo => "self-labelled",
        };
        set.sources
            .push(format!("{} ({rows} {kind} cells)", path.display()));
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
    bar.finish();
    write_atomically(model_path, &model.to_json())?;
    if output.json {
        let doc = json!({
            "output": path_text(model_path),
            "model": model_json(&model, &model_path.display().to_string()),
            "inputs": inputs,
            "config": config,
            "cells": set.len(),
            "samples": model.training.samples,
            "traversable_samples": model.training.traversable_samples,
            "search": model.training.search,
            "solver_iterations": model.training.solver_iterations,
            "solver_converged": model.training.solver_converged,
            "training_ms": model.training.seconds * 1e3,
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
        print_json_summary("train", &selections, doc)?;
    } else if !output.quiet {
        print!("{}", training_text(&model, set.len(), config));
        println!("wrote {}", model_path.display());
    }
    Ok(outcome(&selections))
}
