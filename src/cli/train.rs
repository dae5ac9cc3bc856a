//! `travmap train`: grid search over C and gamma with spatially-blocked CV, a final
//! fit, and the model file; from drives and from Parquet cell datasets.

use std::path::PathBuf;

use anyhow::{Result, bail};
use clap::Args;
use serde_json::json;
use travmap_core::config::ModelChoice;
use travmap_method::classifier::SvmModel;
use travmap_outputs::atomic::write_atomically;
use travmap_outputs::dataset::part_files;
use travmap_outputs::dataset::reading::{Labels, read_training_rows};
use travmap_outputs::labels::read_labels;
use travmap_run::Fingerprints;
use travmap_run::report::tables::training_text;
use travmap_run::scoring::evaluation::{Fit, score_drives};
use travmap_run::scoring::remarks::taught_fit_said;
use travmap_training::crossval::collect_training_set;
use travmap_training::teaching::teach;
use travmap_training::{TrainingSet, train as train_model};

use super::{
    Inputs, Outcome, check_output, frame_count, input_json, model_json, note_extension, outcome,
    path_text, print_json_summary, usage,
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
    /// Learn the given cells (a labels file of `travmap label`, say) together with
    /// this model's support vectors, which stand for what it learnt: `road`,
    /// `offroad` or a model file. The cells weigh training.taught_weight each, C and
    /// gamma are the prior's, and the result is checked against the prior on the
    /// given cells, held out a block of the world at a time.
    #[arg(long, value_name = "MODEL")]
    prior: Option<String>,
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
    let prior_choice = match args.prior.as_deref().map(ModelChoice::named) {
        Some(Ok(choice)) => Some(choice),
        Some(Err(problem)) => return Err(usage(format!("--prior: {problem}"))),
        None => None,
    };
    let prior_file = match &prior_choice {
        Some(ModelChoice::File(path)) => Some(path.as_path()),
        _ => None,
    };
    check_output(model_path, &args.inputs.files(prior_file))?;
    // The prior, checked against the cells' settings before they are read.
    let prior = match &prior_choice {
        Some(choice) => Some(SvmModel::load(choice, config)?),
        None => None,
    };
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
    // Labels files (`travmap label`) name the drives they were asked on.
    let mut labelled_drives: Vec<PathBuf> = Vec::new();
    for path in &datasets {
        if let Ok((_, record)) = read_labels(path) {
            for at in record.asked {
                let drive = PathBuf::from(at.source);
                if drive.exists() && !labelled_drives.contains(&drive) {
                    labelled_drives.push(drive);
                }
            }
        }
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
    let (model, taught) = match &prior {
        Some((prior, prior_name)) => {
            let bar = output.progress(4, "teaching: the check's folds, then the model");
            let (model, check) = teach(&set, prior, config, &|done, total| {
                bar.set_length(total as u64);
                bar.set_position(done as u64);
            })?;
            bar.finish();
            (model, Some((check, prior, prior_name)))
        }
        None => {
            let searches = config.training.c_values.len()
                * config.training.gamma_values.len()
                * config.training.folds
                + 1;
            let bar = output.progress(searches as u64, "grid search + final fit");
            let model = train_model(&set, config, &|done, total| {
                bar.set_length(total as u64);
                bar.set_position(done as u64);
            })?;
            bar.finish();
            (model, None)
        }
    };
    // The drives a labels file's cells were asked on, run by both models: how each
    // fits them.
    let labelled_fit = match (&prior, labelled_drives.is_empty()) {
        (Some((prior, _)), false) => {
            let options = args.inputs.source_options(config)?;
            let mut drives = args
                .inputs
                .open_paths(&labelled_drives, &options, config, false)?;
            for drive in &mut drives {
                drive.source.set_read_labels(false);
            }
            let mut fit = |model: &SvmModel| -> Result<Fit> {
                Ok(score_drives(&mut drives, config, model, || {})?.report.fit)
            };
            Some((fit(&model)?, fit(prior)?))
        }
        _ => None,
    };
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
            "prior": taught.as_ref().map(|(_, prior, name)| model_json(prior, name)),
            "check": taught.as_ref().map(|(check, _, _)| check),
            "fit": labelled_fit.as_ref().map(|(taught, prior)| json!({"taught": taught, "prior": prior})),
        });
        print_json_summary("train", &selections, doc)?;
    } else if !output.quiet {
        print!("{}", training_text(&model, set.len(), config));
        if let Some((check, _, prior_name)) = &taught {
            println!("taught {prior_name}: {}", check.said());
        }
        if let Some((taught, prior)) = &labelled_fit {
            println!("{}", taught_fit_said(taught, prior));
        }
        println!("wrote {}", model_path.display());
    }
    Ok(outcome(&selections))
}
